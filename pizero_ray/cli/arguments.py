"""From declared settings to argparse options: the argparse types, the usage error, the run-dir check.

Every command's parser is built from here before anything heavy loads, so it
imports neither Ray nor JAX.
"""

from __future__ import annotations

import argparse
import json
import types
import typing
from pathlib import Path

from pizero_ray.presets import method_env_notes
from pizero_ray.settings import Setting, declared
from pizero_ray.storage import run_dir as rundir


class UsageError(Exception):
    """Bad input that argparse cannot see: one line on stderr, exit code 2, nothing written."""


def int_at_least(low: int, description: str):
    """An argparse type: an integer >= low, else an error naming the text given."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = low - 1
        if value < low:
            raise argparse.ArgumentTypeError(f"expected a {description} integer, got {text!r}")
        return value

    return parse


positive_int = int_at_least(1, "positive")
non_negative_int = int_at_least(0, "non-negative")


def positive_int_list(text: str) -> tuple[int, ...]:
    """An argparse type: comma-separated positive integers, e.g. 1,10,50."""
    items = text.split(",")
    if not all(item.strip().isdigit() and int(item) > 0 for item in items):
        raise argparse.ArgumentTypeError(f"expected comma-separated positive integers, got {text!r}")
    return tuple(int(item) for item in items)


def env_arg(text: str) -> tuple[str, object]:
    """An argparse type: KEY=VALUE, the value read as JSON where it is JSON (8, false) and as text otherwise."""
    key, sep, raw = text.partition("=")
    if not sep or not key:
        raise argparse.ArgumentTypeError(f"expected KEY=VALUE, got {text!r}")
    try:
        value = json.loads(raw)
    except json.JSONDecodeError:
        value = raw
    return key, value


def comma_list(text: str) -> tuple[str, ...]:
    """An argparse type: comma-separated items, blanks dropped (what they may be is the config's to check)."""
    return tuple(item.strip() for item in text.split(",") if item.strip())


_MINIMUM_WORDS = {0: "non-negative", 1: "positive"}


def _argparse_type(s: Setting) -> dict:
    """add_argument's type and action for a declared setting, from its field's type."""
    kind = s.type
    if typing.get_origin(kind) in (typing.Union, types.UnionType):
        (kind,) = [arg for arg in typing.get_args(kind) if arg is not type(None)]
    if kind is bool:  # a flag: --no-X turns a True default off
        return {"action": "store_false" if s.default else "store_true"}
    if typing.get_origin(kind) is tuple:
        item = typing.get_args(kind)[0]
        if typing.get_origin(item) is tuple:  # (key, value) pairs: --flag KEY=VALUE, repeated
            return {"type": env_arg, "action": "append"}
        return {"type": comma_list}
    if kind is int and s.minimum is not None:
        return {"type": int_at_least(s.minimum, _MINIMUM_WORDS.get(s.minimum, f">= {s.minimum}"))}
    return {"type": None if kind is str else kind}


def _shown(value) -> str:
    if isinstance(value, float):
        return f"{value:g}"
    if isinstance(value, tuple):
        return ",".join(f"{item[0]}={item[1]}" if isinstance(item, tuple) else str(item) for item in value)
    if isinstance(value, dict):
        return ",".join(f"{key}={item}" for key, item in value.items())
    return str(value)


def _help(s: Setting, show_default: bool, defaults: dict | None = None) -> str:
    text = s.help
    notes = method_env_notes(s.name)  # the per-method, per-environment values, from their one table
    if notes:
        text += f" ({'; '.join(notes)})"
    if s.choices is not None:
        text += f" (one of {', '.join(s.allowed)})"
    default = (defaults or {}).get(s.name, s.default if s.has_default else None)
    if show_default and default not in (None, ()) and s.type is not bool:
        text += f" (default {_shown(default)})"
    return text.replace("%", "%%")


def add_settings(parser: argparse.ArgumentParser, cls: type, show_defaults: bool, exclude=(),
                 defaults: dict | None = None) -> None:
    """One option per declared setting of ``cls`` with a flag (but those named in ``exclude``); its default is
    None, so an absent option leaves the dataclass default (or, for the config, the preset's value) in place.
    ``defaults``: the values --help shows where they are not the declared ones (a preset's)."""
    for s in declared(cls):
        if s.flag is not None and s.name not in exclude:
            extra = {"metavar": s.metavar} if s.metavar else {}
            parser.add_argument(s.flag, dest=s.name, default=None, help=_help(s, show_defaults, defaults),
                                **_argparse_type(s), **extra)


def given(cls: type, args) -> dict:
    """The declared settings of ``cls`` given on the command line, by field name."""
    values = {}
    for s in declared(cls):
        value = getattr(args, s.name, None) if s.flag is not None else None
        if value is not None:
            values[s.name] = dict(value) if isinstance(value, list) else value  # KEY=VALUE pairs
    return values


def existing_run(path_text: str, trust_env: bool | str | None = None) -> Path:
    """The run dir named, resolved; one that holds no run is a one-line error naming the path.

    ``trust_env`` (``env_trust(args)``), for a command that builds the run's
    environment: a run dir naming an import path the user has not trusted is
    refused here, before anything runs; None for one that never builds it.
    """
    path = rundir.resolve(path_text)
    if trust_env is None:
        rundir.read_config(path)  # raises a one-line error naming the path
        return path
    config = rundir.read_config(path)
    if isinstance(trust_env, str) and trust_env != config.env:
        raise UsageError(f"--env {trust_env} is not the environment of run dir {path} ({config.env})")
    rundir.read_trusted_config(path, trust_env)
    return path


def add_env_trust_options(parser: argparse.ArgumentParser) -> None:
    """--env and --trust-env: how a user trusts the environment a run dir names by import path."""
    parser.add_argument("--env", dest="trusted_env", metavar="MODULE:FACTORY",
                        help="the run's environment, named again: a run dir that names its environment by import "
                             "path is imported only if you name it here or add --trust-env (docs/running.md, "
                             "Threat model)")
    parser.add_argument("--trust-env", action="store_true",
                        help="import whatever environment the run dir names (its module's code runs)")


def env_trust(args) -> bool | str:
    """What ``add_env_trust_options`` gave: True (--trust-env), the import path named (--env), or False."""
    return True if getattr(args, "trust_env", False) else (getattr(args, "trusted_env", None) or False)
