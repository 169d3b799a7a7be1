"""Playing whole episodes with an agent's parameters: scores, or every step for a renderer.

The loop itself is ``pizero_ray.envs.base.play``, the one every episode in the project is played by.
"""

from __future__ import annotations

from typing import Callable, NamedTuple

import jax

from pizero_ray.agent.networks import Params
from pizero_ray.agent.pizero import Agent
from pizero_ray.envs.base import Environment, Step, play


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


def _play(agent: Agent, params: Params, env: Environment, key: jax.Array, num_episodes: int, record: bool,
          until_all_done: bool = True, recorded: Callable[[Step], object] | None = None):
    """(initial states, final states, scores, recorded steps or None): ``pizero_ray.envs.base.play`` with the agent.

    Unrecorded episodes stop once all have ended (``until_all_done``), or always play to the horizon: the same
    scores, a loop of unknown or of known length. ``record`` keeps each step's state, action, reward and done;
    ``recorded`` keeps what it returns of each step instead."""
    act_key = jax.random.fold_in(key, 1)
    initial_states, observations = jax.vmap(env.reset)(episode_reset_keys(key, num_episodes))

    def policy(states, observations, memory, t):
        return agent.act(params, memory, observations, jax.random.fold_in(act_key, t), env_state=states)

    def kept(step: Step):
        return step.state, step.action, step.reward, step.done

    keep = recorded or (kept if record else None)
    playout = play(jax.vmap(env.step), policy, initial_states, observations, env.spec.horizon, (num_episodes,),
                   policy_carry=agent.initial_memory(num_episodes), record=keep,
                   stop_when_all_done=until_all_done and keep is None)
    return initial_states, playout.final_state, playout.total_reward, playout.recorded


def run_episodes(agent: Agent, params: Params, env: Environment, key: jax.Array, num_episodes: int,
                 until_all_done: bool = True) -> jax.Array:
    """Plays ``num_episodes`` episodes to the horizon; returns their scores [E]. ``until_all_done``: the loop
    stops once every episode has ended (the same scores; config.episode_loop "until_done")."""
    return _play(agent, params, env, key, num_episodes, record=False, until_all_done=until_all_done)[2]


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


def make_plan_use_scorer(agent: Agent, env: Environment, unravel: Callable[[jax.Array], Params], num_episodes: int):
    """jit(theta [D], key) -> (scores [num_episodes], share of actions the ablated plan would change) for an agent
    built with ``make_agent(watch=...)``: the same episodes as ``make_scorer``'s for the same key, played on the
    agent's own plan, and at each of their steps the action the decoder would take from the ablated one."""
    import jax.numpy as jnp

    def score(theta: jax.Array, key: jax.Array):
        def kept(step: Step):
            return step.extra.plan_changed & ~step.ended_before, ~step.ended_before

        _, _, scores, (changed, played) = _play(agent, unravel(theta), env, key, num_episodes, record=False,
                                                recorded=kept)
        return scores, jnp.sum(changed) / jnp.maximum(jnp.sum(played), 1)

    return jax.jit(score)
