"""Self-play episodes and the replay buffer that keeps them: pure JAX, a jitted ring buffer.

Whole episodes are stored (``Episodes``, batch-major [N, T, ...] with T the
environment's horizon): AlphaZero samples positions from them, MuZero
unrolls its model along them. The buffer is a pytree of arrays, so it goes
into the checkpoint with the parameters and a resumed run continues exactly
where an uninterrupted one would be.

Value targets are Monte Carlo returns: the undiscounted sum of the rewards
from a position to the episode's end (every environment here scores an
episode by its total reward over a finite horizon). Past the end, rewards,
values and policies are absorbing: reward 0, value 0, no policy target.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from pizero_ray.envs.base import Environment, Observation, Step
from pizero_ray.envs.base import play as env_play


class Episodes(NamedTuple):
    """A batch of played episodes, [B, T, ...]; steps past an episode's end have ``valid`` False."""

    observation: Observation  # what the agent saw before acting
    action: jax.Array  # int32
    policy: jax.Array  # [B, T, A]: the search's visit distribution (the policy target)
    reward: jax.Array  # float32, 0 past the end
    valid: jax.Array  # bool: the step is part of the episode


def play(search, params, env: Environment, key: jax.Array, num_episodes: int) -> Episodes:
    """Plays ``num_episodes`` episodes to the horizon, each step chosen by ``search``; returns them batch-major.

    The loop is ``pizero_ray.envs.base.play``: once an episode has ended its state stays
    where it ended, and the steps after its end (``valid`` False) keep
    whatever the search chose there.
    """
    reset_keys = jax.random.split(jax.random.fold_in(key, 0), num_episodes)
    states, observations = jax.vmap(env.reset)(reset_keys)
    search_key = jax.random.fold_in(key, 1)

    def policy(states, observations, memory, t):
        out = search(params, observations, states, jax.random.fold_in(search_key, t))
        return out.action.astype(jnp.int32), memory, out.action_weights

    def kept(step: Step) -> Episodes:
        return Episodes(step.observation, step.action, step.extra, step.reward, ~step.ended_before)

    recorded = env_play(jax.vmap(env.step), policy, states, observations, env.spec.horizon, (num_episodes,),
                        record=kept).recorded
    return jax.tree_util.tree_map(lambda x: jnp.swapaxes(x, 0, 1), recorded)


def returns_to_go(reward: jax.Array) -> jax.Array:
    """[.., T] -> [.., T]: the sum of the rewards from each step to the end (0 past the end)."""
    return jnp.flip(jnp.cumsum(jnp.flip(reward, -1), axis=-1), -1)


class Replay(NamedTuple):
    """A ring buffer of ``capacity`` episodes."""

    episodes: Episodes  # [capacity, T, ...]
    filled: jax.Array  # int32: episodes held (up to capacity)
    cursor: jax.Array  # int32: the slot the next episode goes to


def replay_init(episodes: Episodes, capacity: int) -> Replay:
    """An empty buffer shaped like ``episodes`` (any batch), holding ``capacity`` episodes."""
    empty = jax.tree_util.tree_map(lambda x: jnp.zeros((capacity,) + x.shape[1:], x.dtype), episodes)
    return Replay(empty, jnp.int32(0), jnp.int32(0))


def replay_add(replay: Replay, episodes: Episodes) -> Replay:
    """Adds a batch of episodes, overwriting the oldest once full."""
    capacity = replay.episodes.action.shape[0]
    batch = episodes.action.shape[0]
    slots = (replay.cursor + jnp.arange(batch)) % capacity
    stored = jax.tree_util.tree_map(lambda old, new: old.at[slots].set(new), replay.episodes, episodes)
    return Replay(stored, jnp.minimum(replay.filled + batch, capacity), (replay.cursor + batch) % capacity)


class Batch(NamedTuple):
    """Training targets for ``unroll`` steps from sampled positions (AlphaZero: unroll 0)."""

    observation: Observation  # [B, ...] at the sampled position
    actions: jax.Array  # [B, K]: the actions taken from there (any action past the end)
    policy: jax.Array  # [B, K+1, A]
    policy_valid: jax.Array  # [B, K+1]: inside the episode (no policy target past the end)
    value: jax.Array  # [B, K+1]: Monte Carlo returns, 0 past the end
    reward: jax.Array  # [B, K]: the reward of each action, 0 past the end


def replay_sample(replay: Replay, key: jax.Array, batch_size: int, unroll: int) -> Batch:
    """Uniform over the held episodes, then uniform over each one's steps."""
    episode_key, step_key = jax.random.split(key)
    episode = jax.random.randint(episode_key, (batch_size,), 0, jnp.maximum(replay.filled, 1))
    valid = replay.episodes.valid[episode]  # [B, T]
    t = jax.random.categorical(step_key, jnp.where(valid, 0.0, -jnp.inf), axis=-1)  # [B]
    horizon = valid.shape[1]
    steps = t[:, None] + jnp.arange(unroll + 1)  # [B, K+1]
    inside = steps < horizon
    at = jnp.minimum(steps, horizon - 1)

    def gather(x):  # [N, T, ...] -> [B, K+1, ...]
        return x[episode[:, None], at]

    episodes = replay.episodes
    in_episode = gather(episodes.valid) & inside
    value = returns_to_go(episodes.reward)[episode[:, None], at]
    observation = jax.tree_util.tree_map(lambda x: x[episode, t], episodes.observation)
    return Batch(observation, gather(episodes.action)[:, :-1], gather(episodes.policy), in_episode,
                 jnp.where(in_episode, value, 0.0), jnp.where(in_episode, gather(episodes.reward), 0.0)[:, :-1])
