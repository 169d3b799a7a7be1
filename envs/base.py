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
environments need not handle stepping past the end. ``play_policy`` plays a
reference policy (the ``references`` hook's) the same way.

One optional hook is part of the rules, for searches that step a copy of the
environment (AlphaZero's):

* ``reseed(state, key) -> state``: the same state with the randomness it
  keeps for its future (2048's tile draws, Pac-Man's ghosts) redrawn from
  ``key``; None where nothing is random after the reset. A search over
  ``reseed(state, fresh key)`` plans against a sampled future, not the one
  the game will draw.

Three optional hooks live beside the rules, outside the jitted path:

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
    reseed: Callable[[State, jax.Array], State] | None = None


# ---------------------------------------------------------------- checking parameters
#
# Every environment's ``make`` checks its parameters with these, so a bad one
# always reads "<environment>: <parameter> must be <what>, got <value>" on one line.


def _shown(value, limit: int = 80) -> str:
    """``repr(value)`` on one line, cut to ``limit`` characters."""
    text = " ".join(repr(value).split())
    return text if len(text) <= limit else text[:limit - 3] + "..."


def require(ok: bool, env_name: str, name: str, value, expected: str) -> None:
    """Raises ``ValueError("<env_name>: <name> must be <expected>, got <value>")`` unless ``ok``."""
    if not ok:
        raise ValueError(f"{env_name}: {name} must be {expected}, got {_shown(value)}")


def require_int(env_name: str, name: str, value, low: int, high: int | None = None, *, odd: bool = False) -> None:
    """An integer (not a bool) with low <= value (<= high), odd if asked."""
    ok = isinstance(value, int) and not isinstance(value, bool) and low <= value and (high is None or value <= high)
    bound = f"in {low}..{high}" if high is not None else f"at least {low}"
    require(ok and (not odd or value % 2 == 1), env_name, name, value, f"{'an odd' if odd else 'an'} integer {bound}")


def require_bool(env_name: str, name: str, value) -> None:
    """True or False (not 0, 1 or a string)."""
    require(isinstance(value, bool), env_name, name, value, "true or false")


def require_choice(env_name: str, name: str, value, choices) -> None:
    """One of ``choices``."""
    ok = any(type(value) is type(choice) and value == choice for choice in choices)
    require(ok, env_name, name, value, f"one of {', '.join(map(str, choices))}")


def require_path(env_name: str, name: str, value) -> None:
    """A non-empty string naming a file or directory (whether it exists is the loader's to say)."""
    require(isinstance(value, str) and bool(value), env_name, name, value, "a file or directory path")


# ---------------------------------------------------------------- observation helpers


def centred_window(plane: jax.Array, centre: jax.Array, radius: int, fill) -> jax.Array:
    """The ``[2 radius + 1, 2 radius + 1]`` crop of a 2-D ``plane`` centred on the cell ``centre`` (row, column).

    Cells off the plane read ``fill``. Jittable: the crop is a ``dynamic_slice``
    of the plane padded by ``radius`` on every side, so the window's middle cell
    is always ``plane[centre]``.
    """
    padded = jnp.pad(plane, radius, constant_values=fill)
    side = 2 * radius + 1
    return jax.lax.dynamic_slice(padded, (centre[0], centre[1]), (side, side))


# ---------------------------------------------------------------- playing reference policies


class Playout(NamedTuple):
    """What ``play_policy`` returns for one episode."""

    total_reward: jax.Array  # float32: the rewards up to and including the step that ended the episode
    final_state: State  # the state that step reached (or the state after ``horizon`` steps)
    length: jax.Array  # int32: steps taken up to and including that step (``horizon`` if none ended it)


def where_done(done: jax.Array, old, new):
    """``old`` where an episode has ended, else ``new``, leaf by leaf.

    ``done`` is [] for one episode or [B] for a batch whose leaves lead with B:
    a state kept from the step its episode ended on.
    """
    def pick(a, b):
        return jnp.where(done.reshape(done.shape + (1,) * (a.ndim - done.ndim)), a, b)

    return jax.tree_util.tree_map(pick, old, new)


def play_policy(
    step: Callable[[State, jax.Array], tuple[State, Any, jax.Array, jax.Array]],
    policy: Callable[[State, Any, jax.Array], jax.Array],
    initial_state: State,
    horizon: int,
    initial_observation: Any = None,
) -> Playout:
    """Plays one episode of ``policy`` for ``horizon`` steps under ``jax.lax.scan``; pure and jittable.

    ``policy(state, observation, t) -> action`` sees the current state, the
    observation the last step returned (``initial_observation`` before the
    first step) and the step index ``t`` (int32, for ``jax.random.fold_in``
    of the policy's own key, or to index actions drawn in advance). A policy
    that reads only the state needs no ``initial_observation``: then it always
    gets None, and nothing of the observation is kept. ``step`` may return any
    pytree as the observation, e.g. just the action mask, as long as
    ``initial_observation`` has its structure.

    Every one of the ``horizon`` steps is taken (the agent's scored episodes
    stop once all have ended), rewards after ``done`` are ignored and, as in
    the agent's episodes, the state stops changing at ``done``, so
    ``final_state`` is where the episode ended (environments need not handle
    stepping past the end). Batch with vmap.
    """
    keep_observation = initial_observation is not None

    def body(carry, t):
        state, observation, done, total, length = carry
        next_state, next_observation, reward, step_done = step(state, policy(state, observation, t))
        total = total + jnp.where(done, 0.0, reward)
        length = length + ~done
        next_state = where_done(done, state, next_state)
        observation = next_observation if keep_observation else None
        return (next_state, observation, done | step_done, total, length), None

    carry = (initial_state, initial_observation, jnp.bool_(False), jnp.float32(0.0), jnp.int32(0))
    (state, _, _, total, length), _ = jax.lax.scan(body, carry, jnp.arange(horizon))
    return Playout(total, state, length)


def identity_action_features(num_actions: int) -> jax.Array:
    """Action features for environments whose actions have no structure."""
    return jnp.eye(num_actions, dtype=jnp.float32)
