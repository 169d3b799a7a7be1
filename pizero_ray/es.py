"""OpenAI-ES with antithetic pairs, per-member noise, and an optax optimiser.

Pair i's noise z_i is a pure function of (iteration seed, i): any process can
regenerate any member's noise, so only seeds and scalar scores ever travel.
The driver forms the pseudo-gradient
    g = sum_i w_i z_i / (2 sigma n),   w_i = shaped(score_i+) - shaped(score_i-)
chunk by chunk (never more than one chunk of noise in memory) in a fixed order,
and takes an ascent step with Adam.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax

from pizero_ray.config import Config

_NOISE_STREAM, _EPISODE_STREAM = 0, 1


def iteration_seed(base_seed: int, iteration: int) -> int:
    """The seed of one iteration: a pure function of the run's seed and the iteration."""
    return int(np.random.SeedSequence([base_seed, iteration]).generate_state(1, np.uint32)[0])


def iteration_key(seed) -> jax.Array:
    return jax.random.PRNGKey(jnp.asarray(seed, jnp.uint32))


def pair_noise(key: jax.Array, pair_index: jax.Array, size: int) -> jax.Array:
    """z_i ~ N(0, I) for pair i, from the iteration key and the index alone."""
    pair_key = jax.random.fold_in(key, pair_index)
    return jax.random.normal(jax.random.fold_in(pair_key, _NOISE_STREAM), (size,), jnp.float32)


def pair_episode_key(key: jax.Array, pair_index: jax.Array) -> jax.Array:
    """The episodes pair i plays: the same for both of its members."""
    return jax.random.fold_in(jax.random.fold_in(key, pair_index), _EPISODE_STREAM)


def centered_ranks(x: jax.Array, valid: jax.Array | None = None) -> jax.Array:
    """Ranks scaled to [-0.5, 0.5] (Salimans et al. 2017); ties broken by position.

    Entries where ``valid`` is False take no rank and come back as 0.
    """
    flat = x.reshape(-1)
    valid_flat = jnp.ones(flat.shape, bool) if valid is None else jnp.broadcast_to(valid, x.shape).reshape(-1)
    order = jnp.argsort(jnp.where(valid_flat, flat, jnp.inf), stable=True)  # invalid entries rank last
    ranks = jnp.empty_like(flat, dtype=jnp.float32).at[order].set(jnp.arange(flat.size, dtype=jnp.float32))
    count = jnp.sum(valid_flat)
    shaped = ranks / jnp.maximum(count - 1, 1).astype(jnp.float32) - 0.5
    return jnp.where(valid_flat, shaped, 0.0).reshape(x.shape)


def pair_weights(scores: jax.Array, fitness_shaping: str, valid: jax.Array | None = None) -> jax.Array:
    """Per-pair weight w_i from scores [n, 2] (columns: +z, -z); 0 for pairs not ``valid``."""
    pair_valid = None if valid is None else valid[:, None]
    shaped = centered_ranks(scores, pair_valid) if fitness_shaping == "centered_ranks" else scores
    weights = shaped[:, 0] - shaped[:, 1]
    return weights if valid is None else jnp.where(valid, weights, 0.0)


def pseudo_gradient(
    key: jax.Array, weights: jax.Array, sigma: float, size: int, chunk_size: int, num_pairs: jax.Array | None = None
) -> jax.Array:
    """sum_i w_i z_i / (2 sigma n), regenerating the noise one chunk at a time.

    ``num_pairs`` is n when some weights are zero because their pairs were dropped.
    """
    total_pairs = weights.shape[0]
    chunks = weights.reshape(total_pairs // chunk_size, chunk_size)
    starts = jnp.arange(0, total_pairs, chunk_size)

    def add_chunk(total, chunk):
        start, chunk_weights = chunk
        noise = jax.vmap(pair_noise, in_axes=(None, 0, None))(key, start + jnp.arange(chunk_size), size)
        return total + chunk_weights @ noise, None

    total, _ = jax.lax.scan(add_chunk, jnp.zeros((size,), jnp.float32), (starts, chunks))
    return total / (2.0 * sigma * (total_pairs if num_pairs is None else num_pairs))


def make_optimizer(config: Config) -> optax.GradientTransformation:
    # optax minimises: it is handed -g. Decoupled-from-nothing L2 decay is
    # added to that loss gradient, as OpenAI-ES's l2 coefficient does.
    return optax.chain(optax.add_decayed_weights(config.weight_decay), optax.adam(config.learning_rate))


class UpdateStats(NamedTuple):
    gradient_norm: jax.Array
    update_norm: jax.Array
    parameter_norm: jax.Array


def make_update(config: Config, size: int):
    """jit(theta, opt_state, iteration_seed, scores [n, 2], valid [n]) -> (theta, opt_state, stats).

    ``valid`` marks the pairs whose scores came in (all of them unless a run
    lets iterations finish early with ``min_fraction``).
    """
    optimizer = make_optimizer(config)

    def update(theta, opt_state, seed, scores, valid):
        weights = pair_weights(scores, config.fitness_shaping, valid)
        num_pairs = jnp.maximum(jnp.sum(valid), 1).astype(jnp.float32)
        g = pseudo_gradient(iteration_key(seed), weights, config.sigma, size, config.chunk_size, num_pairs)
        updates, opt_state = optimizer.update(-g, opt_state, theta)
        new_theta = optax.apply_updates(theta, updates)
        stats = UpdateStats(jnp.linalg.norm(g), jnp.linalg.norm(updates), jnp.linalg.norm(new_theta))
        return new_theta, opt_state, stats

    return optimizer, jax.jit(update)
