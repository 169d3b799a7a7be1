"""The environment protocol: a small bundle of pure, jittable functions.

An environment is explicit state plus two pure functions, in the spirit of
Jumanji: ``reset(key) -> (state, observation)`` and
``step(state, action) -> (state, observation, reward, done)``. Both must be
jittable and vmappable, with no Python control flow on traced values.

Every observation carries what any agent needs to act, whatever the action
space:

* ``vector``: a flat float vector (what the encoder sees). A partially
  observable environment simply puts less in it.
* ``action_features``: one row of features per discrete action, so a decoder
  can score candidates with one shared network (pointer-style). Environments
  without per-action structure use the identity (one-hot rows). Continuous
  environments have an empty ``[0, F]`` array.
* ``action_mask``: which discrete actions are legal now (all True when every
  action is legal; empty for continuous actions).

Episodes have a fixed horizon: after ``done`` the rollout ignores rewards, so
environments need not handle stepping past the end.

Two optional hooks live beside the rules, outside the jitted path:

* ``render(state) -> uint8 [H, W, 3]``: draws one unbatched state (NumPy/PIL).
* ``references(initial_states, scores) -> dict``: reference solvers or
  policies evaluated on the same initial states as the agent (batched, leading
  dimension = episodes), reported by ``pizero eval`` next to the agent's score.
* ``episode_metrics(final_states) -> dict[str, array [E]]``: what else an
  episode's end says about the agent (2048's highest tile, say); ``pizero
  eval`` reports the mean of each as ``mean_<name>``.
"""

from __future__ import annotations

from typing import Any, Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np


class Observation(NamedTuple):
    vector: jax.Array  # [observation_size] float32
    action_features: jax.Array  # [num_actions, action_feature_size] float32
    action_mask: jax.Array  # [num_actions] bool


class EnvSpec(NamedTuple):
    """Static shapes of an environment, known before anything is traced."""

    observation_size: int
    horizon: int  # the episode always ends at or before this many steps
    num_actions: int  # discrete actions; 0 for continuous environments
    action_feature_size: int  # columns of Observation.action_features
    action_dim: int = 0  # continuous action size; 0 for discrete environments
    action_low: float = 0.0  # bounds of every continuous action component
    action_high: float = 1.0

    @property
    def discrete(self) -> bool:
        return self.num_actions > 0

    @property
    def action_input_size(self) -> int:
        """Size of the vector that describes a taken action to the memory."""
        return self.action_feature_size if self.discrete else self.action_dim


State = Any  # each environment defines its own NamedTuple


class Environment(NamedTuple):
    name: str
    spec: EnvSpec
    reset: Callable[[jax.Array], tuple[State, Observation]]
    step: Callable[[State, jax.Array], tuple[State, Observation, jax.Array, jax.Array]]
    render: Callable[[State], np.ndarray] | None = None
    references: Callable[[State, np.ndarray], dict[str, float]] | None = None
    episode_metrics: Callable[[State], dict[str, np.ndarray]] | None = None


def require_int(env_name: str, name: str, value, low: int, high: int | None = None) -> None:
    """A one-line ValueError naming the environment, the parameter and the value unless low <= value (<= high)."""
    if isinstance(value, bool) or not isinstance(value, int) or value < low or (high is not None and value > high):
        bound = f"in {low}..{high}" if high is not None else f"at least {low}"
        raise ValueError(f"{env_name}: {name} must be an integer {bound}, got {value!r}")


def identity_action_features(num_actions: int) -> jax.Array:
    """Action features for environments whose actions have no structure."""
    return jnp.eye(num_actions, dtype=jnp.float32)
