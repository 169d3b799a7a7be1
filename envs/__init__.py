"""JAX-native environments for PiZero; see ``envs.base`` for the protocol.

Each environment module provides ``make(**params) -> Environment``. The
training presets that suit an environment (horizon-dependent population sizes,
say) are the trainer's: ``pizero_ray.presets.ENV_PRESETS``.
"""

from __future__ import annotations

import importlib
from typing import Any

from envs.base import Environment, EnvSpec, Observation

# name -> (module, extra factory arguments)
_REGISTRY: dict[str, tuple[str, dict[str, Any]]] = {
    "tsp": ("envs.tsp", {}),
    "collect": ("envs.collect", {}),
    "flp": ("envs.flp", {"objective": "max"}),
    "flp-mean": ("envs.flp", {"objective": "mean"}),
    "2048": ("envs.game2048", {}),
    "pacman": ("envs.pacman", {"partial": False}),
    "pacman-po": ("envs.pacman", {"partial": True}),
    "sokoban": ("envs.sokoban", {}),
}

ENV_NAMES = tuple(sorted(_REGISTRY))


def _module(name: str):
    if name not in _REGISTRY:
        raise ValueError(f"unknown environment {name!r}; choose from {', '.join(ENV_NAMES)}")
    return importlib.import_module(_REGISTRY[name][0])


def make(name: str, **env_args) -> Environment:
    """Builds an environment by name; unknown names or bad parameters raise a one-line ValueError."""
    module = _module(name)
    try:
        return module.make(**_REGISTRY[name][1], **env_args)
    except TypeError as error:
        raise ValueError(f"bad parameters for environment {name!r}: {env_args} ({error})") from None


__all__ = ["ENV_NAMES", "EnvSpec", "Environment", "Observation", "make"]
