"""Playing whole episodes with an agent's parameters: scores, or every step for a renderer."""

from __future__ import annotations

from typing import Callable, NamedTuple

import jax
import jax.numpy as jnp

from envs.base import Environment, where_done
from pizero_ray.agent.networks import Params
from pizero_ray.agent.pizero import Agent


def episode_reset_keys(key: jax.Array, num_episodes: int) -> jax.Array:
    """The reset keys ``run_episodes`` uses, so evaluations can rebuild its instances."""
    return jax.random.split(jax.random.fold_in(key, 0), num_episodes)


class Trajectory(NamedTuple):
    """What ``record_episodes`` returns: everything a renderer needs, time-major."""

    initial_state: object  # env state pytree, leading dim E
    states: object  # env state after each step, leading dims [T, E]
    actions: jax.Array  # [T, E] (or [T, E, d] for continuous actions)
    rewards: jax.Array  # [T, E], zero after the episode ended
    dones: jax.Array  # [T, E]: the episode had ended by this step
    scores: jax.Array  # [E]


def _play(agent: Agent, params: Params, env: Environment, key: jax.Array, num_episodes: int, record: bool):
    act_key = jax.random.fold_in(key, 1)
    initial_states, observations = jax.vmap(env.reset)(episode_reset_keys(key, num_episodes))
    memory = agent.initial_memory(num_episodes)
    done = jnp.zeros((num_episodes,), bool)
    score = jnp.zeros((num_episodes,), jnp.float32)

    def step(carry, t):
        states, observations, memory, done, score = carry
        action, memory, _ = agent.act(params, memory, observations, jax.random.fold_in(act_key, t), env_state=states)
        stepped, observations, reward, step_done = jax.vmap(env.step)(states, action)
        # An ended episode keeps its final state, so final-state metrics do not depend on how long the others ran.
        states = where_done(done, states, stepped)
        reward = jnp.where(done, 0.0, reward)
        done = done | step_done
        out = (states, action, reward, done) if record else None
        return (states, observations, memory, done, score + reward), out

    carry = (initial_states, observations, memory, done, score)
    if record:
        carry, recorded = jax.lax.scan(step, carry, jnp.arange(env.spec.horizon))
    else:
        carry, recorded = _until_all_done(step, carry, env.spec.horizon), None
    final_states, score = carry[0], carry[-1]
    return initial_states, final_states, score, recorded


def _until_all_done(step, carry, horizon: int):
    """``step`` for t = 0, 1, ... as ``lax.scan`` over ``arange(horizon)`` would, stopping once every episode
    has ended (``carry[3]``, ``_play``'s done flags, all True).

    A step after every episode ended adds nothing (rewards are masked, states
    kept), so the scores are the scan's; games that end long before the
    horizon (2048, Sokoban when solved) stop paying for it. Under ``vmap`` over
    the population the loop runs until the last member's episodes end.
    """

    def unfinished(loop):
        t, carry = loop
        return (t < horizon) & ~jnp.all(carry[3])

    def body(loop):
        t, carry = loop
        return t + 1, step(carry, t)[0]

    return jax.lax.while_loop(unfinished, body, (jnp.int32(0), carry))[1]


def run_episodes(agent: Agent, params: Params, env: Environment, key: jax.Array, num_episodes: int) -> jax.Array:
    """Plays ``num_episodes`` episodes to the horizon; returns their scores [E]."""
    return _play(agent, params, env, key, num_episodes, record=False)[2]


def record_episodes(agent: Agent, params: Params, env: Environment, key: jax.Array, num_episodes: int) -> Trajectory:
    """Like ``run_episodes`` (same episodes for the same key), keeping every step."""
    initial_states, _, scores, (states, actions, rewards, dones) = _play(agent, params, env, key, num_episodes, True)
    return Trajectory(initial_states, states, actions, rewards, dones, scores)


def make_scorer(
    agent: Agent, env: Environment, unravel: Callable[[jax.Array], Params], num_episodes: int,
    final_states: bool = False,
):
    """jit(theta [D], key) -> scores [num_episodes] of the unperturbed agent (and final states if asked)."""

    def score(theta: jax.Array, key: jax.Array):
        _, last, scores, _ = _play(agent, unravel(theta), env, key, num_episodes, record=False)
        return (scores, last) if final_states else scores

    return jax.jit(score)
