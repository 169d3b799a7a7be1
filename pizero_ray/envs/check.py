"""Checking an environment against the protocol (``pizero_ray.envs.base``) before anything trains on it.

``check_environment`` traces ``reset`` and ``step`` with ``jax.eval_shape``
(no compile, no episode played) and compares what they return with the
spec, so that a user's environment that breaks the protocol fails with one
line naming the problem and the environment, not with a traceback from deep
inside the rollout's ``lax.scan``. Pure: it only reads the environment.
"""

from __future__ import annotations

import numbers
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from pizero_ray.envs.base import Environment, EnvSpec, Observation

# What tracing raises when Python control flow or NumPy meets a traced value: the function is not jittable.
_TRACER_ERRORS = (jax.errors.ConcretizationTypeError, jax.errors.TracerArrayConversionError,
                  jax.errors.NonConcreteBooleanIndexError, jax.errors.UnexpectedTracerError)
_OPTIONAL_HOOKS = ("render", "references", "episode_metrics", "reseed")


def _problem(source: str, text: str) -> ValueError:
    return ValueError(f"environment {source!r}: {text}")


def _described(value: Any) -> str:
    """An abstract array as dtype[shape] (float32[5]), anything else as its type's name."""
    if hasattr(value, "shape") and hasattr(value, "dtype"):
        return f"{np.dtype(value.dtype).name}[{','.join(map(str, value.shape))}]"
    return type(value).__name__


def _first_line(error: BaseException) -> str:
    lines = str(error).strip().splitlines()
    return f"{type(error).__name__}: {lines[0] if lines else ''}".rstrip(": ")


def check_spec(spec: Any, source: str) -> None:
    """Every EnvSpec field of the right type and range; discrete or continuous, not both."""
    if not isinstance(spec, EnvSpec):
        raise _problem(source, f"spec must be a pizero_ray.envs.base.EnvSpec, got {type(spec).__name__}")

    def whole(name: str, low: int) -> None:
        value = getattr(spec, name)
        if not (isinstance(value, numbers.Integral) and not isinstance(value, bool) and value >= low):
            raise _problem(source, f"spec.{name} must be an integer at least {low}, got {value!r}")

    for name, low in (("observation_size", 1), ("horizon", 1), ("num_actions", 0), ("action_feature_size", 0),
                      ("action_dim", 0)):
        whole(name, low)
    for name in ("action_low", "action_high"):
        value = getattr(spec, name)
        if not (isinstance(value, numbers.Real) and not isinstance(value, bool)):
            raise _problem(source, f"spec.{name} must be a number, got {value!r}")
    if (spec.num_actions > 0) == (spec.action_dim > 0):
        raise _problem(source, "spec must have num_actions > 0 (discrete) or action_dim > 0 (continuous), "
                               f"not {'both' if spec.num_actions else 'neither'}: got num_actions={spec.num_actions}, "
                               f"action_dim={spec.action_dim}")
    if not spec.discrete and not spec.action_low < spec.action_high:
        raise _problem(source, f"spec.action_low must be below spec.action_high, got {spec.action_low!r} and "
                               f"{spec.action_high!r}")


def _check_observation(observation: Any, spec: EnvSpec, source: str, where: str) -> None:
    """The observation's three arrays with the shapes and dtypes the spec implies."""
    if not isinstance(observation, Observation):
        raise _problem(source, f"{where} must return a pizero_ray.envs.base.Observation, got {_described(observation)}")
    expected = {"vector": ((spec.observation_size,), jnp.float32),
                "action_features": ((spec.num_actions, spec.action_feature_size), jnp.float32),
                "action_mask": ((spec.num_actions,), jnp.bool_)}
    for field, (shape, dtype) in expected.items():
        value = getattr(observation, field)
        if not hasattr(value, "shape") or tuple(value.shape) != shape or np.dtype(value.dtype) != np.dtype(dtype):
            want = f"{np.dtype(dtype).name}[{','.join(map(str, shape))}]"
            raise _problem(source, f"{where}'s observation.{field} must be {want} (from the spec), "
                                   f"got {_described(value)}")


def _traced(function, args: tuple, source: str, where: str):
    """``jax.eval_shape(function, *args)``: shapes only, no compile; what goes wrong is one line."""
    try:
        return jax.eval_shape(function, *args)
    except _TRACER_ERRORS as error:
        raise _problem(source, f"{where} is not jittable: Python control flow or NumPy on a traced value "
                               f"(use jnp.where or jax.lax.cond) ({_first_line(error)})") from None
    except Exception as error:  # noqa: BLE001 -- the user's code: whatever it raises becomes the one line
        raise _problem(source, f"{where} failed while tracing: {_first_line(error)}") from None


def _tuple_of(value: Any, length: int, source: str, where: str, names: str) -> tuple:
    if not isinstance(value, tuple) or len(value) != length:
        raise _problem(source, f"{where} must return a tuple ({names}), got {_described(value)}"
                               + (f" of {len(value)}" if isinstance(value, tuple) else ""))
    return value


def _same_state(reset_state: Any, step_state: Any, source: str, where: str) -> None:
    """The state a step returns has the reset's structure, shapes and dtypes (the rollout's scan carries it)."""
    def leaves(tree):
        flat, structure = jax.tree_util.tree_flatten(tree)
        return structure, [_described(leaf) for leaf in flat]

    if leaves(reset_state) != leaves(step_state):
        raise _problem(source, f"{where} must return a state like reset's (the same structure, shapes and dtypes): "
                               f"reset gives {leaves(reset_state)[1]}, {where} gives {leaves(step_state)[1]}")


def check_environment(env: Any, source: str | None = None) -> Environment:
    """``env``, if it keeps the protocol; else a one-line ValueError "environment '<source>': <problem>".

    ``source``: how the user named the environment (its import path); ``env.name`` if not given.
    """
    source = source or str(getattr(env, "name", env))
    if not isinstance(env, Environment):
        raise _problem(source, f"the factory must return a pizero_ray.envs.base.Environment, got {type(env).__name__}")
    if not isinstance(env.name, str) or not env.name:
        raise _problem(source, f"name must be a non-empty string, got {env.name!r}")
    check_spec(env.spec, source)
    for hook in ("reset", "step"):
        if not callable(getattr(env, hook)):
            raise _problem(source, f"{hook} must be a function, got {type(getattr(env, hook)).__name__}")
    for hook in _OPTIONAL_HOOKS:
        if getattr(env, hook) is not None and not callable(getattr(env, hook)):
            raise _problem(source, f"{hook} must be a function or None, got {type(getattr(env, hook)).__name__}")
    spec = env.spec
    key = jax.ShapeDtypeStruct((2,), jnp.uint32)  # a jax.random.PRNGKey
    state, observation = _tuple_of(_traced(env.reset, (key,), source, "reset"), 2, source, "reset",
                                   "state, observation")
    _check_observation(observation, spec, source, "reset")
    action = (jax.ShapeDtypeStruct((), jnp.int32) if spec.discrete
              else jax.ShapeDtypeStruct((spec.action_dim,), jnp.float32))
    stepped = _tuple_of(_traced(env.step, (state, action), source, "step"), 4, source, "step",
                        "state, observation, reward, done")
    next_state, next_observation, reward, done = stepped
    _same_state(state, next_state, source, "step")
    _check_observation(next_observation, spec, source, "step")
    if tuple(getattr(reward, "shape", (None,))) != () or not jnp.issubdtype(reward.dtype, jnp.floating):
        raise _problem(source, f"step's reward must be a float scalar (shape ()), got {_described(reward)}")
    if tuple(getattr(done, "shape", (None,))) != () or done.dtype != jnp.bool_:
        raise _problem(source, f"step's done must be a bool scalar (shape ()), got {_described(done)}")
    if env.reseed is not None:
        _same_state(state, _traced(env.reseed, (state, key), source, "reseed"), source, "reseed")
    _check_batched(env, action, source)
    if spec.discrete:
        _check_legal_actions(env, source)
    return env


BATCH = 2  # episodes side by side in the vmap check


def _check_batched(env: Environment, action: Any, source: str) -> None:
    """reset and step under ``jax.vmap``, as the workers play a batch of episodes: traced, not run."""
    keys = jax.ShapeDtypeStruct((BATCH, 2), jnp.uint32)
    states, _ = _traced(jax.vmap(env.reset), (keys,), source, "reset under jax.vmap")
    actions = jax.ShapeDtypeStruct((BATCH, *action.shape), action.dtype)
    _traced(jax.vmap(env.step), (states, actions), source, "step under jax.vmap")


LEGAL_ACTION_STEPS = 4  # steps of one episode whose masks are checked: the check plays, so it stays short


def _check_legal_actions(env: Environment, source: str) -> None:
    """The first observations of one episode (random legal actions) each leave an action legal: an all-False
    mask would have the agent take an illegal action silently. Plays them: one small compile each of reset and
    step."""
    found = _first_without_legal_action(env, source)
    if found is not None:
        raise _problem(source, f"{found}'s observation.action_mask has no legal action: at least one action must "
                               "always be legal")


def _first_without_legal_action(env: Environment, source: str) -> str | None:
    """"reset" or "step N", the first of one short episode whose mask is all False; None if none is."""
    from pizero_ray.envs.base import random_legal_action

    key = jax.random.PRNGKey(0)
    try:
        state, observation = jax.jit(env.reset)(key)
        step = jax.jit(env.step)
        for number in range(min(LEGAL_ACTION_STEPS, env.spec.horizon) + 1):
            if not bool(observation.action_mask.any()):
                return "reset" if number == 0 else f"step {number}"
            key, action_key = jax.random.split(key)
            state, observation, _, done = step(state, random_legal_action(observation.action_mask, action_key))
            if bool(done):
                return None
    except Exception as error:  # noqa: BLE001 -- the user's code: whatever it raises becomes the one line
        raise _problem(source, f"playing its first steps failed: {_first_line(error)}") from None
    return None
