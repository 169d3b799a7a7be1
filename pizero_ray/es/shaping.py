"""Fitness shaping: from the pairs' scores to their weights in the pseudo-gradient."""

from __future__ import annotations

import jax
import jax.numpy as jnp


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
