"""Corridor: a small environment of your own, named by import path (``--env examples.corridor:make``).

The agent stands in a corridor of ``length`` cells and walks to the goal cell,
both placed at random. Each step moves it one cell left or right; a move into
the wall is masked. Reaching the goal scores 1 and ends the episode; every step
costs 1 / horizon, so the straight walk scores most (random walks score less).
docs/your-environment.md walks through this file.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from pizero_ray.envs.base import Environment, EnvSpec, Observation, require_int

LEFT, RIGHT = 0, 1
NUM_ACTIONS = 2
CELL = 16  # pixels per cell in the drawing
FLOOR, GOAL, AGENT, WALL = (235, 235, 235), (60, 170, 80), (40, 90, 200), (90, 90, 90)


class CorridorState(NamedTuple):
    position: jax.Array  # int32: the agent's cell
    goal: jax.Array  # int32: the goal's cell
    t: jax.Array  # int32: steps taken


def make(length: int = 8) -> Environment:
    require_int("corridor", "length", length, 2)  # a bad --env-arg is a one-line error naming it
    horizon = 2 * length  # every episode ends by then: enough to walk the corridor and back

    def observe(state: CorridorState) -> Observation:
        vector = jnp.concatenate([jax.nn.one_hot(state.position, length), jax.nn.one_hot(state.goal, length),
                                  jnp.array([state.t / horizon], jnp.float32)])
        # One row per action (left, right): which action it is, and how far it would take the agent toward the
        # goal. Identity rows alone would do; a feature that says what the action does is one the decoder,
        # which scores every row with one network, can use from its first iterations.
        toward = (state.goal - state.position) / length * jnp.array([-1.0, 1.0])
        action_features = jnp.concatenate([jnp.eye(NUM_ACTIONS), toward[:, None]], axis=1).astype(jnp.float32)
        action_mask = jnp.array([state.position > 0, state.position < length - 1])  # no walking into walls
        return Observation(vector, action_features, action_mask)

    def reset(key: jax.Array) -> tuple[CorridorState, Observation]:
        position, goal = jax.random.choice(key, length, (2,), replace=False)  # two different cells
        state = CorridorState(position.astype(jnp.int32), goal.astype(jnp.int32), jnp.int32(0))
        return state, observe(state)

    def step(state: CorridorState, action: jax.Array):
        move = jnp.where(action == RIGHT, 1, -1)  # jnp.where, not `if`: step is traced, never run on values
        position = jnp.clip(state.position + move, 0, length - 1).astype(jnp.int32)
        state = CorridorState(position, state.goal, state.t + 1)
        arrived = position == state.goal
        reward = jnp.where(arrived, 1.0, 0.0) - 1.0 / horizon
        done = arrived | (state.t >= horizon)
        return state, observe(state), reward, done

    spec = EnvSpec(observation_size=2 * length + 1, horizon=horizon, num_actions=NUM_ACTIONS,
                   action_feature_size=NUM_ACTIONS + 1)
    return Environment("corridor", spec, reset, step, render=functools.partial(render, length=length),
                       episode_metrics=episode_metrics)


def render(state: CorridorState, length: int) -> np.ndarray:
    """One unbatched state as uint8 [CELL, length * CELL, 3]: the goal cell green, the agent a blue square."""
    image = np.full((CELL, length * CELL, 3), FLOOR, np.uint8)
    goal, agent, margin = int(state.goal) * CELL, int(state.position) * CELL, CELL // 4
    image[:, goal:goal + CELL] = GOAL
    image[margin:CELL - margin, agent + margin:agent + CELL - margin] = AGENT  # the goal shows around it
    image[:, ::CELL] = image[:, -1:] = WALL  # lines between cells, and the far wall
    return image


def episode_metrics(final_states: CorridorState) -> dict[str, np.ndarray]:
    """What `pizero eval` reports beside the score (as mean_arrived): the share of episodes that reached the goal."""
    return {"arrived": np.asarray(final_states.position == final_states.goal, np.float32)}
