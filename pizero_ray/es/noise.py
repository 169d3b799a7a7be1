"""Per-pair noise: a pure function of (iteration seed, pair index), full rank or low rank.

Pair i's noise z_i is a pure function of (iteration seed, i): any process can
regenerate any member's noise, so only seeds and scalar scores ever travel.

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


def weighted_noise_sum(weights: jax.Array, noise: jax.Array, perturbation: Perturbation,
                       one_loop: bool = False) -> jax.Array:
    """sum_i w_i z_i [D] for a chunk: weights [C], noise [C, noise_size].

    For low-rank matrices, sum_i w_i A_i B_i^T is a sum of C r outer products,
    added in a fixed order (``_outer_products_in_order``), not one
    [n, C r] x [C r, m] matrix product: a product's blocking, and so its
    rounding, follows the number of threads the process has (a 1-core worker
    and a 2-core driver disagreed in the last bits on Collect), and a part
    must be the same bits wherever it is computed.

    ``one_loop``: every matrix's sum advances in one loop instead of a loop per
    matrix; the same additions in the same order, so the same bits. A GPU
    launches kernels for each trip of each loop; on 2 CPU cores one loop was
    10-35% slower (the bench agent, chunks of 32 and 256), so it is the GPU
    workers' choice (``chunk_scoring.ChunkScorer``).
    """
    if perturbation.rank == 0:
        return weights @ noise
    scale = 1.0 / np.sqrt(perturbation.rank)
    split = split_noise(noise, perturbation)
    factors = [((weights[:, None, None] * part[0]).reshape(-1, part[0].shape[-1]),
                part[1].reshape(-1, part[1].shape[-1])) for part in split if isinstance(part, tuple)]
    sums = iter(_outer_products_in_one_loop(factors) if one_loop
                else [_outer_products_in_order(left, right) for left, right in factors])
    return jnp.concatenate([(next(sums) * scale).reshape(-1) if isinstance(part, tuple)
                            else weights @ part.reshape(part.shape[0], -1) for part in split])


def _outer_products_in_order(left: jax.Array, right: jax.Array) -> jax.Array:
    """sum_k outer(left[k], right[k]) [n, m], added k by k: elementwise work only, the same bits on any number
    of threads."""

    def add(total, rows):
        return total + rows[0][:, None] * rows[1][None, :], None

    total, _ = jax.lax.scan(add, jnp.zeros((left.shape[1], right.shape[1]), left.dtype), (left, right))
    return total


def _outer_products_in_one_loop(factors: list[tuple[jax.Array, jax.Array]]) -> list[jax.Array]:
    """``_outer_products_in_order`` of each (left [K, n], right [K, m]), every sum advancing in one loop."""
    if not factors:
        return []

    def add(totals, rows):
        return [total + left[:, None] * right[None, :] for total, (left, right) in zip(totals, rows)], None

    zeros = [jnp.zeros((left.shape[1], right.shape[1]), left.dtype) for left, right in factors]
    return jax.lax.scan(add, zeros, factors)[0]


def pair_noise(key: jax.Array, pair_index: jax.Array, size: int) -> jax.Array:
    """z_i ~ N(0, I) for pair i, from the iteration key and the index alone."""
    pair_key = jax.random.fold_in(key, pair_index)
    return jax.random.normal(jax.random.fold_in(pair_key, _NOISE_STREAM), (size,), jnp.float32)


def pair_episode_key(key: jax.Array, pair_index: jax.Array) -> jax.Array:
    """The episodes pair i plays: the same for both of its members."""
    return jax.random.fold_in(jax.random.fold_in(key, pair_index), _EPISODE_STREAM)


def chunk_noise(key: jax.Array, first_pair: jax.Array, chunk_size: int, noise_size: int) -> jax.Array:
    """The noise [C, noise_size] of the chunk of pairs first_pair .. first_pair + C - 1."""
    pairs = first_pair + jnp.arange(chunk_size)
    return jax.vmap(pair_noise, in_axes=(None, 0, None))(key, pairs, noise_size)
