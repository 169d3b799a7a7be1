"""JAX-native environments for PiZero; see ``envs.base`` for the protocol."""

from __future__ import annotations

from typing import Callable

from envs.base import Environment, EnvSpec, Observation

# name -> factory taking the environment's parameters as keyword arguments
_REGISTRY: dict[str, Callable[..., Environment]] = {}


def _register() -> None:
    from envs import tsp

    _REGISTRY["tsp"] = tsp.make


_register()

ENV_NAMES = tuple(sorted(_REGISTRY))


def make(name: str, **env_args) -> Environment:
    """Builds an environment by name; unknown names or parameters raise ValueError."""
    if name not in _REGISTRY:
        raise ValueError(f"unknown environment {name!r}; choose from {', '.join(ENV_NAMES)}")
    try:
        return _REGISTRY[name](**env_args)
    except TypeError as error:
        raise ValueError(f"bad parameters for environment {name!r}: {env_args} ({error})") from None


__all__ = ["ENV_NAMES", "EnvSpec", "Environment", "Observation", "make"]
