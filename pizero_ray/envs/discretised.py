"""A continuous-action environment seen through a grid of discrete actions.

The gradient-trained baselines (AlphaZero, MuZero) search over discrete
actions, so on FLP they choose among ``points_per_dim ** action_dim`` grid
points: cell centres of a regular grid over the action bounds (16 x 16 = 256
points on FLP by default). Each action's features are its point, rescaled to
[0, 1], so the pointer-style policy head scores points by where they lie.
Rewards, renderer, references and episode metrics are the wrapped
environment's: scores stay comparable with agents that act continuously.
"""

from __future__ import annotations

import itertools

import jax.numpy as jnp

from pizero_ray.envs.base import Environment, Observation, require, require_int


def grid_points(points_per_dim: int, action_dim: int, low: float, high: float) -> jnp.ndarray:
    """[points_per_dim ** action_dim, action_dim]: the cell centres, the last component varying fastest."""
    axis = [low + (high - low) * (i + 0.5) / points_per_dim for i in range(points_per_dim)]
    return jnp.asarray(list(itertools.product(axis, repeat=action_dim)), jnp.float32)


def discretise(env: Environment, points_per_dim: int) -> Environment:
    """``env`` with its continuous actions replaced by grid points (an environment with discrete actions)."""
    spec = env.spec
    require(not spec.discrete, env.name, "action space", "discrete", "continuous (only those are discretised)")
    require_int(env.name, "points_per_dim", points_per_dim, 1)
    points = grid_points(points_per_dim, spec.action_dim, spec.action_low, spec.action_high)
    features = (points - spec.action_low) / (spec.action_high - spec.action_low)
    legal = jnp.ones((points.shape[0],), bool)

    def observe(observation: Observation) -> Observation:
        return Observation(observation.vector, features, legal)

    def reset(key):
        state, observation = env.reset(key)
        return state, observe(observation)

    def step(state, action):
        state, observation, reward, done = env.step(state, points[action.astype(jnp.int32)])
        return state, observe(observation), reward, done

    discrete_spec = spec._replace(num_actions=int(points.shape[0]), action_feature_size=spec.action_dim, action_dim=0)
    return env._replace(spec=discrete_spec, reset=reset, step=step)
