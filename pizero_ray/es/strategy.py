"""OpenAI-ES's update: the pseudo-gradient from per-chunk parts, and an optax optimiser.

The pseudo-gradient
    g = sum_i w_i z_i / (2 sigma n),   w_i = shaped(score_i+) - shaped(score_i-)
is a sum of per-chunk parts (``GradientParts``), added in chunk order: the
worker that evaluated a chunk computes its part from the noise it kept, the
driver regenerates the noise of any other (one chunk in memory at a time).
Then Adam takes an ascent step.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax

from pizero_ray.config import Config
from pizero_ray.es.noise import Perturbation, chunk_noise, iteration_key, weighted_noise_sum
from pizero_ray.es.shaping import pair_weights


def pseudo_gradient(
    key: jax.Array,
    weights: jax.Array,
    sigma: float,
    perturbation: Perturbation,
    chunk_size: int,
    num_pairs: jax.Array | None = None,
) -> jax.Array:
    """sum_i w_i z_i / (2 sigma n) in one function, regenerating the noise one chunk at a time.

    The reference the trainer's chunk-by-chunk ``GradientParts`` are tested
    against. ``num_pairs`` is n when some weights are zero because their pairs
    were dropped.
    """
    size, noise_size = perturbation.parameter_size, perturbation.noise_size
    total_pairs = weights.shape[0]
    chunks = weights.reshape(total_pairs // chunk_size, chunk_size)
    starts = jnp.arange(0, total_pairs, chunk_size)

    def add_chunk(total, chunk):
        start, chunk_weights = chunk
        noise = chunk_noise(key, start, chunk_size, noise_size)
        return total + weighted_noise_sum(chunk_weights, noise, perturbation), None

    total, _ = jax.lax.scan(add_chunk, jnp.zeros((size,), jnp.float32), (starts, chunks))
    return total / (2.0 * sigma * (total_pairs if num_pairs is None else num_pairs))


class GradientParts(NamedTuple):
    """The pseudo-gradient chunk by chunk: each chunk's share sum_{i in chunk} w_i z_i, wherever it is computed.

    A worker computes a chunk's part from the noise it kept from evaluating the
    chunk, anyone else from regenerated noise: both go through the same
    ``part`` function on the same noise, so the part is the same bits either
    way, and ``total`` adds the parts in chunk order.
    """

    noise: object  # jit(iteration_seed, first_pair) -> noise [C, noise_size]
    part: object  # jit(weights [C], noise [C, noise_size]) -> [D]
    chunk_size: int

    def from_noise(self, weights: np.ndarray, noise) -> np.ndarray:
        """The part of a chunk whose noise is at hand (kept from its evaluation, or regenerated)."""
        return np.asarray(self.part(np.asarray(weights, np.float32), noise), np.float32)

    def regenerated(self, seed, first_pair: int, weights: np.ndarray) -> np.ndarray:
        return self.from_noise(weights, self.noise(np.uint32(seed), np.int32(first_pair)))

    @staticmethod
    def total(parts) -> np.ndarray:
        """sum of the parts, added one by one in the given (chunk) order."""
        total = None
        for part in parts:
            total = np.array(part, np.float32) if total is None else total + part
        return total


def gradient_parts(config: Config, perturbation: Perturbation) -> GradientParts:
    noise_size, chunk = perturbation.noise_size, config.chunk_size

    def noise(seed, first_pair):
        return chunk_noise(iteration_key(seed), first_pair, chunk, noise_size)

    def part(weights, noise):
        return weighted_noise_sum(weights, noise, perturbation)

    return GradientParts(jax.jit(noise), jax.jit(part), chunk)


def make_optimizer(config: Config) -> optax.GradientTransformation:
    # optax minimises: it is handed -g. Decoupled-from-nothing L2 decay is
    # added to that loss gradient, as OpenAI-ES's l2 coefficient does.
    return optax.chain(optax.add_decayed_weights(config.weight_decay), optax.adam(config.learning_rate))


class UpdateStats(NamedTuple):
    gradient_norm: jax.Array
    update_norm: jax.Array
    parameter_norm: jax.Array


class Update(NamedTuple):
    """The driver's update in its three steps (so that the middle one can run on the workers)."""

    optimizer: optax.GradientTransformation
    weights: object  # jit(scores [n, 2], valid [n]) -> (w [n], number of valid pairs)
    parts: GradientParts
    step: object  # jit(theta, opt_state, sum of the parts, number of valid pairs) -> (theta, opt_state, stats)
    parameter_size: int

    def part_here(self, seed, weights: np.ndarray, chunk_index: int) -> np.ndarray:
        """One chunk's part from regenerated noise (zeros for a chunk whose weights are all zero)."""
        chunk = self.parts.chunk_size
        chunk_weights = weights[chunk_index * chunk:(chunk_index + 1) * chunk]
        if not chunk_weights.any():
            return np.zeros(self.parameter_size, np.float32)
        return self.parts.regenerated(seed, chunk_index * chunk, chunk_weights)

    def __call__(self, theta, opt_state, seed, scores, valid):
        """The whole update in this process: every chunk's part from regenerated noise, one chunk at a time."""
        weights, num_pairs = self.weights(scores, valid)
        weights = np.asarray(weights)
        parts = (self.part_here(seed, weights, index) for index in range(weights.shape[0] // self.parts.chunk_size))
        return self.step(theta, opt_state, GradientParts.total(parts), num_pairs)


def make_update(config: Config, perturbation: Perturbation) -> Update:
    """The update: (theta, opt_state, iteration_seed, scores [n, 2], valid [n]) -> (theta, opt_state, stats).

    ``valid`` marks the pairs whose scores came in (all of them unless a run
    lets iterations finish early with ``min_fraction``).
    """
    optimizer = make_optimizer(config)

    def weights(scores, valid):
        return pair_weights(scores, config.fitness_shaping, valid), jnp.maximum(jnp.sum(valid), 1)

    def step(theta, opt_state, parts_total, num_pairs):
        g = parts_total / (2.0 * config.sigma * num_pairs.astype(jnp.float32))
        updates, opt_state = optimizer.update(-g, opt_state, theta)
        new_theta = optax.apply_updates(theta, updates)
        stats = UpdateStats(jnp.linalg.norm(g), jnp.linalg.norm(updates), jnp.linalg.norm(new_theta))
        return new_theta, opt_state, stats

    return Update(optimizer, jax.jit(weights), gradient_parts(config, perturbation), jax.jit(step),
                  perturbation.parameter_size)
