"""JAX-native environments for PiZero; see ``pizero_ray.envs.base`` for the protocol.

Each environment module provides ``make(**params) -> Environment``; an
environment of your own is named by import path instead of registered here
(``make("mypackage.mymodule:make")``, ``pizero_ray.envs.import_path``). The
training presets that suit an environment (horizon-dependent population sizes,
say) are the trainer's: ``pizero_ray.presets.ENV_PRESETS``.
"""

from __future__ import annotations

import importlib
from typing import Any

from pizero_ray.envs.base import Environment, EnvSpec, Observation

# name -> (module, extra factory arguments)
_REGISTRY: dict[str, tuple[str, dict[str, Any]]] = {
    "tsp": ("pizero_ray.envs.tsp", {}),
    "collect": ("pizero_ray.envs.collect", {}),
    "flp": ("pizero_ray.envs.flp", {"objective": "max"}),
    "flp-mean": ("pizero_ray.envs.flp", {"objective": "mean"}),
    "2048": ("pizero_ray.envs.game2048", {}),
    "pacman": ("pizero_ray.envs.pacman", {"partial": False}),
    "pacman-po": ("pizero_ray.envs.pacman", {"partial": True}),
    "sokoban": ("pizero_ray.envs.sokoban", {}),
}

ENV_NAMES = tuple(sorted(_REGISTRY))


def is_import_path(name: str) -> bool:
    """Whether ``name`` names an environment of your own, ``module:factory`` (registered names have no colon)."""
    return isinstance(name, str) and ":" in name


def _module(name: str):
    if name not in _REGISTRY:
        raise ValueError(f"unknown environment {name!r}; choose from {', '.join(ENV_NAMES)}, "
                         "or name your own by import path module:factory")
    return importlib.import_module(_REGISTRY[name][0])


def make(name: str, **env_args) -> Environment:
    """Builds an environment by name, or by import path ``module:factory`` (an environment of your own,
    checked against the protocol: ``pizero_ray.envs.import_path``); unknown names or bad parameters raise a one-line
    ValueError."""
    if is_import_path(name):
        from pizero_ray.envs import import_path

        return import_path.make(name, **env_args)
    module = _module(name)
    try:
        return module.make(**_REGISTRY[name][1], **env_args)
    except TypeError as error:
        raise ValueError(f"bad parameters for environment {name!r}: {env_args} ({error})") from None


__all__ = ["ENV_NAMES", "EnvSpec", "Environment", "Observation", "is_import_path", "make"]
