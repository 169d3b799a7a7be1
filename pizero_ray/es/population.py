"""The population rollout: the hot path, pure JAX, one jitted function.

``make_pair_scorer`` builds the function a worker runs: for a chunk of pair
indices and their noise, it plays the same episodes with theta + sigma z and
theta - sigma z and returns their mean scores [C, 2]. The noise comes in from
``es.GradientParts.noise`` (a pure function of the iteration seed and the
chunk), the very function that regenerates it for the chunk's share of the
gradient: the noise a worker keeps from scoring a chunk and the noise anyone
regenerates are the output of one program, the same bits by construction.
Nothing but the flat parameters, a seed and indices travels to a worker.
"""

from __future__ import annotations

import math
from typing import Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax.flatten_util import ravel_pytree

from pizero_ray.agent import make_agent, networks
from pizero_ray.agent.episodes import run_episodes
from pizero_ray.agent.networks import Params
from pizero_ray.config import Config
from pizero_ray.envs.base import Environment
from pizero_ray.es import noise as es_noise


class FlatParams(NamedTuple):
    """How the agent's parameter pytree maps to the flat vector ES works on, and how noise maps onto it."""

    size: int
    unravel: Callable[[jax.Array], Params]
    perturbation: es_noise.Perturbation


def flat_params(config: Config, env: Environment) -> tuple[jax.Array, FlatParams]:
    """Initial parameters (from config.seed) as a flat float32 vector, and its layout."""
    params = make_agent(config, env.spec).init(jax.random.PRNGKey(config.seed))
    theta, _ = ravel_pytree(params)
    return theta.astype(jnp.float32), _layout_of(params, config.perturbation_rank)


def params_layout(config: Config, env: Environment) -> FlatParams:
    """The flat vector's layout from the parameters' shapes alone, for whoever gets theta from elsewhere.

    A worker needs the layout, not the initial values: tracing ``init`` under
    ``jax.eval_shape`` runs nothing, where calling it runs each of its ops
    eagerly, one small compile apiece (measured on a CPU core, the tiny TSP
    agent: a worker's ``__init__`` took 4.4 s with the compile cache cold and
    2.8 s warm, 2.5 s and 2.1 s from the layout alone). The values stay eager
    in ``flat_params``: a jitted ``init`` fuses ops and rounds some initial
    parameters differently, in the last bit.
    """
    shapes = jax.eval_shape(make_agent(config, env.spec).init, jax.random.PRNGKey(config.seed))
    return _layout_of(shapes, config.perturbation_rank)


def _layout_of(params, rank: int) -> FlatParams:
    """The layout of a parameter pytree whose leaves have a shape and a dtype (arrays or ShapeDtypeStructs),
    in ``ravel_pytree``'s order; its ``unravel`` does what ``ravel_pytree``'s does, without needing values."""
    leaves, treedef = jax.tree.flatten(params)
    sizes = [math.prod(leaf.shape) for leaf in leaves]
    splits = np.cumsum(sizes)[:-1]

    def unravel(theta: jax.Array) -> Params:
        parts = jnp.split(theta, splits)
        return jax.tree.unflatten(treedef, [part.reshape(leaf.shape).astype(leaf.dtype)
                                            for part, leaf in zip(parts, leaves)])

    perturbation = es_noise.Perturbation(tuple(leaf.shape for leaf in leaves), rank)
    return FlatParams(sum(sizes), unravel, perturbation)


def perturbed_params(theta: jax.Array, noise: jax.Array, step: jax.Array, layout: FlatParams) -> Params:
    """The member theta + step * z without forming z: low-rank matrices stay factored.

    ``step`` is +sigma or -sigma. Only for low-rank perturbations; with full-rank
    noise the member is simply ``layout.unravel(theta + step * noise)``.
    """
    perturbation = layout.perturbation
    center = layout.unravel(theta)
    leaves, treedef = jax.tree.flatten(center)
    scale = step / jnp.sqrt(jnp.float32(perturbation.rank))
    members = [
        networks.LowRankPerturbed(leaf, scale * part[0], part[1]) if isinstance(part, tuple) else leaf + step * part
        for leaf, part in zip(leaves, es_noise.split_noise(noise, perturbation))
    ]
    return jax.tree.unflatten(treedef, members)


def make_pair_scorer(config: Config, env: Environment, layout: FlatParams):
    """jit(theta [D], iteration_seed uint32, pair_indices [C], noise [C, noise_size]) -> scores [C, 2] (+z, -z).

    ``noise`` is the pairs' noise as ``es.gradient_parts(...).noise`` makes it
    for the chunk; the episodes each pair plays still come from (iteration
    seed, pair index) alone, or with ``common_episodes`` from the iteration
    seed alone: the same for every pair, new every iteration.
    """
    agent, sigma, episodes = make_agent(config, env.spec), config.sigma, config.episodes_per_member
    until_all_done = config.episode_loop == "until_done"
    # Whose episodes a pair plays: its own (from its index), or with common_episodes pair 0's, every pair alike.
    episodes_of = (lambda pair_index: jnp.zeros_like(pair_index)) if config.common_episodes else (lambda i: i)

    def member_score(theta: jax.Array, episode_key: jax.Array) -> jax.Array:
        return jnp.mean(run_episodes(agent, layout.unravel(theta), env, episode_key, episodes, until_all_done))

    def low_rank_member_score(theta: jax.Array, noise: jax.Array, step: jax.Array, episode_key: jax.Array):
        params = perturbed_params(theta, noise, step, layout)
        return jnp.mean(run_episodes(agent, params, env, episode_key, episodes, until_all_done))

    def pair_scores(theta: jax.Array, key: jax.Array, pair_index: jax.Array, noise: jax.Array) -> jax.Array:
        episode_key = es_noise.pair_episode_key(key, episodes_of(pair_index))  # both halves see the same episodes
        if layout.perturbation.rank > 0:
            steps = jnp.array([sigma, -sigma], jnp.float32)
            return jax.vmap(low_rank_member_score, in_axes=(None, None, 0, None))(theta, noise, steps, episode_key)
        members = jnp.stack([theta + sigma * noise, theta - sigma * noise])
        return jax.vmap(member_score, in_axes=(0, None))(members, episode_key)

    def evaluate(theta: jax.Array, iteration_seed: jax.Array, pair_indices: jax.Array, noise: jax.Array):
        key = es_noise.iteration_key(iteration_seed)
        return jax.vmap(pair_scores, in_axes=(None, None, 0, 0))(theta, key, pair_indices, noise)

    return jax.jit(evaluate)
