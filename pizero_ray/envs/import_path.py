"""Environments of your own, named by import path: ``--env mypackage.mymodule:make``.

``module:factory`` names a function in an importable module; it is called
with the ``--env-arg`` parameters and returns a ``pizero_ray.envs.base.Environment``,
which ``pizero_ray.envs.check`` checks before anything trains on it.

Where the module is found (docs/your-environment.md): as ``python -m``
finds it, in the directory ``pizero`` runs in first, then on PYTHONPATH
and among the installed packages. Ray hands that directory to the workers
(it puts the driver's working directory on their ``sys.path``); on a
cluster, ``ray job submit --working-dir DIR`` ships DIR to every node and
runs ``pizero`` in it.
"""

from __future__ import annotations

import importlib
import os
import sys
from typing import Callable

from pizero_ray.envs.base import Environment
from pizero_ray.envs.check import check_environment

EXAMPLE = "examples.corridor:make"


def parse(path: str) -> tuple[str, str]:
    """(module, factory) of ``module:factory``; a malformed path is a one-line ValueError naming it."""
    module, _, factory = path.partition(":")
    if not (all(part.isidentifier() for part in module.split(".")) and factory.isidentifier()):
        raise ValueError(f"environment {path!r}: an import path must read module:factory "
                         f"(e.g. {EXAMPLE}), with a dotted module name and a function name")
    return module, factory


def _import(path: str, module_name: str):
    """The module, imported as ``python -m`` would: from the working directory first."""
    here = os.getcwd()
    if here not in sys.path and "" not in sys.path:  # the `pizero` console script does not put it there
        sys.path.insert(0, here)
    try:
        return importlib.import_module(module_name)
    except ModuleNotFoundError as error:
        if error.name and (module_name == error.name or module_name.startswith(error.name + ".")):
            raise ValueError(f"environment {path!r}: no module named {error.name!r} in {here} (where pizero runs), "
                             "on PYTHONPATH or among the installed packages") from None
        raise ValueError(f"environment {path!r}: importing {module_name} failed: {error}") from None
    except Exception as error:  # noqa: BLE001 -- the user's module: whatever it raises becomes one line
        lines = str(error).strip().splitlines()
        raise ValueError(f"environment {path!r}: importing {module_name} raised {type(error).__name__}: "
                         f"{lines[0] if lines else ''}") from None


def factory(path: str) -> Callable[..., Environment]:
    """The function ``module:factory`` names; a missing module or attribute is a one-line ValueError."""
    module_name, name = parse(path)
    module = _import(path, module_name)
    if not hasattr(module, name):
        where = getattr(module, "__file__", None) or "a namespace package"
        raise ValueError(f"environment {path!r}: module {module_name} ({where}) has no attribute {name!r}")
    found = getattr(module, name)
    if not callable(found):
        raise ValueError(f"environment {path!r}: {name} must be a function returning a "
                         "pizero_ray.envs.base.Environment, "
                         f"got {type(found).__name__}")
    return found


def make(path: str, **env_args) -> Environment:
    """The environment ``module:factory(**env_args)`` returns, checked against the protocol
    (``pizero_ray.envs.check``)."""
    build = factory(path)
    try:
        env = build(**env_args)
    except TypeError as error:  # as for registered environments: an unknown or missing parameter
        raise ValueError(f"bad parameters for environment {path!r}: {env_args} ({error})") from None
    except ValueError as error:  # the factory's own check of a parameter (envs.base.require): kept to one line
        raise ValueError(" ".join(str(error).split())) from None
    except Exception as error:  # noqa: BLE001 -- the user's factory: whatever it raises becomes one line
        lines = str(error).strip().splitlines()
        raise ValueError(f"environment {path!r}: the factory raised {type(error).__name__}: "
                         f"{lines[0] if lines else ''}".rstrip(": ")) from None
    return check_environment(env, path)
