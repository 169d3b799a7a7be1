"""OpenAI-ES with antithetic pairs, per-member noise, and an optax optimiser.

Pair i's noise z_i is a pure function of (iteration seed, i): any process can
regenerate any member's noise, so only seeds and scalar scores ever travel.
The pseudo-gradient
    g = sum_i w_i z_i / (2 sigma n),   w_i = shaped(score_i+) - shaped(score_i-)
is a sum of per-chunk parts (``GradientParts``), added in chunk order: the
worker that evaluated a chunk computes its part from the noise it kept, the
driver regenerates the noise of any other (one chunk in memory at a time).
Then Adam takes an ascent step.

With ``perturbation_rank`` r > 0 (opt-in, after EGGROLL, Sarkar et al. 2025)
every weight matrix's noise is low rank, E = A B^T / sqrt(r) with A, B standard
normal: each entry still has unit variance, but a pair draws (n + m) r numbers
per n x m matrix instead of n m, and a member's forward pass is the shared
product x W plus a cheap rank-r term. Biases keep full Gaussian noise.
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


class Perturbation(NamedTuple):
    """How one pair's noise vector maps onto the flat parameters."""

    leaf_shapes: tuple[tuple[int, ...], ...]  # the parameter pytree's leaves, in ravel order
    rank: int  # 0: full-rank Gaussian noise; r > 0: rank-r noise on every weight matrix

    def is_low_rank(self, shape: tuple[int, ...]) -> bool:
        return self.rank > 0 and len(shape) == 2

    @property
    def parameter_size(self) -> int:
        return sum(int(np.prod(shape)) for shape in self.leaf_shapes)

    @property
    def noise_size(self) -> int:
        """Standard normals drawn per pair."""
        return sum((shape[0] + shape[1]) * self.rank if self.is_low_rank(shape) else int(np.prod(shape))
                   for shape in self.leaf_shapes)


def split_noise(noise: jax.Array, perturbation: Perturbation) -> list:
    """Per leaf: the factors (A^T [r, n], B^T [r, m]) of a low-rank matrix, else the leaf's own noise.

    ``noise`` is [..., noise_size]; leading dimensions are kept. The factors are
    stored rank-major: a member's x A is then r contiguous dot products, which
    XLA's CPU backend batches over members far better than a product with a
    trailing dimension of size r.
    """
    lead = noise.shape[:-1]
    parts, offset = [], 0
    for shape in perturbation.leaf_shapes:
        if perturbation.is_low_rank(shape):
            (n, m), r = shape, perturbation.rank
            a = noise[..., offset:offset + n * r].reshape(lead + (r, n))
            b = noise[..., offset + n * r:offset + (n + m) * r].reshape(lead + (r, m))
            parts.append((a, b))
            offset += (n + m) * r
        else:
            size = int(np.prod(shape))
            parts.append(noise[..., offset:offset + size].reshape(lead + shape))
            offset += size
    return parts


def expand_noise(noise: jax.Array, perturbation: Perturbation) -> jax.Array:
    """One pair's direction in parameter space, z [D]: A B^T / sqrt(r) for low-rank matrices."""
    if perturbation.rank == 0:
        return noise
    scale = 1.0 / np.sqrt(perturbation.rank)
    parts = [(part[0].T @ part[1] * scale).reshape(-1) if isinstance(part, tuple) else part.reshape(-1)
             for part in split_noise(noise, perturbation)]
    return jnp.concatenate(parts)


def weighted_noise_sum(weights: jax.Array, noise: jax.Array, perturbation: Perturbation) -> jax.Array:
    """sum_i w_i z_i [D] for a chunk: weights [C], noise [C, noise_size].

    For low-rank matrices, sum_i w_i A_i B_i^T is one [n, C r] x [C r, m]
    product instead of C outer products.
    """
    if perturbation.rank == 0:
        return weights @ noise
    scale = 1.0 / np.sqrt(perturbation.rank)
    parts = []
    for part in split_noise(noise, perturbation):
        if isinstance(part, tuple):
            a, b = part  # [C, r, n], [C, r, m]
            weighted = (weights[:, None, None] * a).reshape(-1, a.shape[-1])
            parts.append((weighted.T @ b.reshape(-1, b.shape[-1]) * scale).reshape(-1))
        else:
            parts.append((weights @ part.reshape(part.shape[0], -1)))
    return jnp.concatenate(parts)


def pair_noise(key: jax.Array, pair_index: jax.Array, size: int) -> jax.Array:
    """z_i ~ N(0, I) for pair i, from the iteration key and the index alone."""
    pair_key = jax.random.fold_in(key, pair_index)
    return jax.random.normal(jax.random.fold_in(pair_key, _NOISE_STREAM), (size,), jnp.float32)


def pair_episode_key(key: jax.Array, pair_index: jax.Array) -> jax.Array:
    """The episodes pair i plays: the same for both of its members."""
    return jax.random.fold_in(jax.random.fold_in(key, pair_index), _EPISODE_STREAM)


def centered_ranks(x: jax.Array, valid: jax.Array | None = None) -> jax.Array:
    """Ranks scaled to [-0.5, 0.5] (Salimans et al. 2017); tied scores share their average rank.

    Ties matter for integer scores (goals covered, coins): broken by position,
    a pair whose members tie would get a non-zero weight, and a population that
    ties throughout would step along -sum z_i, a random direction. With average
    ranks a tied pair weighs 0 and an all-tied population gives no step.
    Entries where ``valid`` is False take no rank and come back as 0.
    """
    flat = x.reshape(-1).astype(jnp.float32)
    valid_flat = jnp.ones(flat.shape, bool) if valid is None else jnp.broadcast_to(valid, x.shape).reshape(-1)
    keyed = jnp.where(valid_flat, flat, jnp.inf)  # invalid entries rank last
    ordered = jnp.sort(keyed)
    first = jnp.searchsorted(ordered, keyed, side="left")  # entries below this one
    last = jnp.searchsorted(ordered, keyed, side="right") - 1  # ... and up to its last tie
    ranks = (first + last).astype(jnp.float32) / 2.0
    count = jnp.sum(valid_flat)
    shaped = ranks / jnp.maximum(count - 1, 1).astype(jnp.float32) - 0.5
    return jnp.where(valid_flat, shaped, 0.0).reshape(x.shape)


def pair_weights(scores: jax.Array, fitness_shaping: str, valid: jax.Array | None = None) -> jax.Array:
    """Per-pair weight w_i from scores [n, 2] (columns: +z, -z); 0 for pairs not ``valid``."""
    pair_valid = None if valid is None else valid[:, None]
    shaped = centered_ranks(scores, pair_valid) if fitness_shaping == "centered_ranks" else scores
    weights = shaped[:, 0] - shaped[:, 1]
    return weights if valid is None else jnp.where(valid, weights, 0.0)


def chunk_noise(key: jax.Array, first_pair: jax.Array, chunk_size: int, noise_size: int) -> jax.Array:
    """The noise [C, noise_size] of the chunk of pairs first_pair .. first_pair + C - 1."""
    pairs = first_pair + jnp.arange(chunk_size)
    return jax.vmap(pair_noise, in_axes=(None, 0, None))(key, pairs, noise_size)


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
