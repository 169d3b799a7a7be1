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
    """What ``play`` (and ``play_policy``, for one episode) returns."""

    total_reward: jax.Array  # float32: the rewards up to and including the step that ended the episode
    final_state: State  # the state that step reached (or the state after ``horizon`` steps)
    length: jax.Array  # int32: steps taken up to and including that step (``horizon`` if none ended it)
    recorded: Any = None  # what ``record`` kept of each step, time-major [T, ...]; None without one


def where_done(done: jax.Array, old, new):
    """``old`` where an episode has ended, else ``new``, leaf by leaf.

    ``done`` is [] for one episode or [B] for a batch whose leaves lead with B:
    a state kept from the step its episode ended on.
    """
    def pick(a, b):
        return jnp.where(done.reshape(done.shape + (1,) * (a.ndim - done.ndim)), a, b)

    return jax.tree_util.tree_map(pick, old, new)


class Step(NamedTuple):
    """One step of ``play``, as ``record`` sees it."""

    observation: Any  # what the policy saw (the observation before the action)
    action: jax.Array
    extra: Any  # what the policy returned beside its action (a search's visit counts, say)
    state: State  # the state after the step (kept from the end once the episode has ended)
    reward: jax.Array  # 0 once the episode had ended before this step
    ended_before: jax.Array  # bool: the episode had ended before this step (the step is not part of it)
    done: jax.Array  # bool: the episode has ended by the end of this step


def play(
    step: Callable[[State, jax.Array], tuple[State, Any, jax.Array, jax.Array]],
    policy: Callable[[State, Any, Any, jax.Array], tuple[jax.Array, Any, Any]],
    initial_state: State,
    initial_observation: Any,
    horizon: int,
    done_shape: tuple[int, ...] = (),
    policy_carry: Any = None,
    record: Callable[[Step], Any] | None = None,
    stop_when_all_done: bool = False,
) -> Playout:
    """Plays episodes for ``horizon`` steps, masked at their ends: the one episode loop; pure and jittable.

    ``policy(state, observation, policy_carry, t) -> (action, policy_carry,
    extra)`` chooses at step ``t`` (int32: for ``jax.random.fold_in`` of its
    own key, or to index actions drawn in advance) from the current state and
    the last observation; ``policy_carry`` is its own memory. ``step`` plays
    one step of one episode, or of a batch (``done_shape`` (B,) and a vmapped
    ``step``). Once an episode has ended its rewards are ignored and its state
    stops changing, so ``final_state`` is where it ended (environments need
    not handle stepping past the end); the observations go on as ``step``
    returns them. ``record(Step) -> pytree`` keeps what it returns of every
    step. ``stop_when_all_done`` (without ``record``) stops once every episode
    has ended instead of playing to the horizon: a step after that adds
    nothing, so the totals are the same, and games that end long before the
    horizon stop paying for it.
    """

    def body(carry, t):
        state, observation, memory, done, total, length = carry
        action, memory, extra = policy(state, observation, memory, t)
        stepped, next_observation, reward, step_done = step(state, action)
        reward = jnp.where(done, 0.0, reward)
        next_state = where_done(done, state, stepped)
        now_done = done | step_done
        kept = record(Step(observation, action, extra, next_state, reward, done, now_done)) if record else None
        return (next_state, next_observation, memory, now_done, total + reward, length + ~done), kept

    done = jnp.zeros(done_shape, bool)
    carry = (initial_state, initial_observation, policy_carry, done, jnp.zeros(done_shape, jnp.float32),
             jnp.zeros(done_shape, jnp.int32))
    if stop_when_all_done and record is None:
        carry, recorded = _until_all_done(body, carry, horizon), None
    else:
        carry, recorded = jax.lax.scan(body, carry, jnp.arange(horizon))
    state, _, _, _, total, length = carry
    return Playout(total, state, length, recorded)


def _until_all_done(body, carry, horizon: int):
    """``body`` for t = 0, 1, ... as ``lax.scan`` over ``arange(horizon)`` would, stopping once every episode has
    ended (``carry[3]``, ``play``'s done flags). Under ``vmap`` over a population the loop runs until the last
    member's episodes end."""

    def unfinished(loop):
        t, carry = loop
        return (t < horizon) & ~jnp.all(carry[3])

    def next_step(loop):
        t, carry = loop
        return t + 1, body(carry, t)[0]

    return jax.lax.while_loop(unfinished, next_step, (jnp.int32(0), carry))[1]


def play_policy(
    step: Callable[[State, jax.Array], tuple[State, Any, jax.Array, jax.Array]],
    policy: Callable[[State, Any, jax.Array], jax.Array],
    initial_state: State,
    horizon: int,
    initial_observation: Any = None,
) -> Playout:
    """Plays one episode of ``policy`` for ``horizon`` steps (``play``, unbatched); pure and jittable.

    ``policy(state, observation, t) -> action`` sees the current state, the
    observation the last step returned (``initial_observation`` before the
    first step) and the step index ``t``. A policy that reads only the state
    needs no ``initial_observation``: then it always gets None, and nothing of
    the observation is kept. ``step`` may return any pytree as the
    observation, e.g. just the action mask, as long as
    ``initial_observation`` has its structure. Every one of the ``horizon``
    steps is taken. Batch with vmap.
    """
    keep_observation = initial_observation is not None

    def chosen(state, observation, memory, t):
        return policy(state, observation, t), memory, None

    def stepped(state, action):
        next_state, observation, reward, done = step(state, action)
        return next_state, observation if keep_observation else None, reward, done

    return play(stepped, chosen, initial_state, initial_observation, horizon)


def identity_action_features(num_actions: int) -> jax.Array:
    """Action features for environments whose actions have no structure."""
    return jnp.eye(num_actions, dtype=jnp.float32)


# ---------------------------------------------------------------- reference players
#
# 2048 and Pac-Man measure their ``references`` the same way: players that choose
# with a key of their own, played from the agent's initial states, every player
# on the same fixed keys, each per-episode metric averaged.


def random_legal_action(action_mask: jax.Array, key: jax.Array) -> jax.Array:
    """A uniformly random legal action (action 0 when none is legal: the episode is over then anyway)."""
    return jax.random.categorical(key, jnp.where(action_mask, 0.0, -jnp.inf)).astype(jnp.int32)


def reference_player(
    step: Callable[[State, jax.Array], tuple[State, Any, jax.Array, jax.Array]],
    policy: Callable[[State, Any, jax.Array], jax.Array],
    horizon: int,
    summarise: Callable[[Playout], tuple[jax.Array, ...]],
    initial_observation_of: Callable[[State], Any] | None = None,
):
    """jit(initial states [E], keys [E]) -> ``summarise(playout)`` of each episode, batched: ``policy`` to the horizon.

    ``policy(state, observation, key)`` gets ``fold_in(episode key, t)`` at step
    ``t``, so a random policy draws afresh every step yet replays exactly from
    the same keys. ``step``, ``initial_observation_of`` and the observation are
    as in ``play_policy`` (no ``initial_observation_of``: the policy gets None).
    """

    def one_episode(initial_state: State, key: jax.Array):
        def keyed_policy(state, observation, t):
            return policy(state, observation, jax.random.fold_in(key, t))

        initial_observation = None if initial_observation_of is None else initial_observation_of(initial_state)
        return summarise(play_policy(step, keyed_policy, initial_state, horizon, initial_observation))

    return jax.jit(jax.vmap(one_episode))


def mean_reference_metrics(players: dict, metric_names: tuple[str, ...], initial_states: State,
                           seed: int) -> dict[str, float]:
    """Each player's per-episode metrics on ``initial_states`` [E], averaged, as ``{"<player>_<metric>": mean}``.

    A player is a ``reference_player``: it returns one [E] array per name in
    ``metric_names``. Every player gets the same keys, split from ``seed``: the
    figures are reproducible, and the players meet the same luck.
    """
    episodes = jax.tree_util.tree_leaves(initial_states)[0].shape[0]
    keys = jax.random.split(jax.random.PRNGKey(seed), episodes)
    means = {}
    for player_name, player in players.items():
        for metric, values in zip(metric_names, player(initial_states, keys), strict=True):
            means[f"{player_name}_{metric}"] = float(np.mean(np.asarray(values)))
    return means


def fresh_initial_states(env: Environment, episodes: int, seed: int) -> State:
    """``episodes`` initial states [E] reset from keys split from ``seed`` (to measure references outside an eval)."""
    states, _ = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.PRNGKey(seed), episodes))
    return states
