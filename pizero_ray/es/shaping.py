"""Fitness shaping: from the pairs' scores to their weights in the pseudo-gradient.

A score that is not finite (NaN, +inf or -inf) comes from a broken episode,
never from a good one: it counts as the lowest score of the iteration. With
centred ranks it ranks below every finite score (sorted as it is, NaN would
rank above +inf, as the best); with raw scores (shaping ``none``) it takes the
lowest finite score's value, so no NaN or infinity reaches the parameters.
The driver counts such scores in its metrics, warns, and stops the run when
no finite score is left (``trainer.driver``).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp


def _valid_mask(x: jax.Array, valid: jax.Array | None) -> jax.Array:
    return jnp.ones(x.shape, bool) if valid is None else jnp.broadcast_to(valid, x.shape)


def centered_ranks(x: jax.Array, valid: jax.Array | None = None) -> jax.Array:
    """Ranks scaled to [-0.5, 0.5] (Salimans et al. 2017); tied scores share their average rank.

    Ties matter for integer scores (goals covered, coins): broken by position,
    a pair whose members tie would get a non-zero weight, and a population that
    ties throughout would step along -sum z_i, a random direction. With average
    ranks a tied pair weighs 0 and an all-tied population gives no step.
    Entries where ``valid`` is False take no rank and come back as 0; entries
    that are not finite tie for the lowest rank.
    """
    flat = x.reshape(-1).astype(jnp.float32)
    valid_flat = _valid_mask(x, valid).reshape(-1)
    lowest_if_broken = jnp.where(jnp.isfinite(flat), flat, -jnp.inf)
    keyed = jnp.where(valid_flat, lowest_if_broken, jnp.inf)  # invalid entries rank last
    ordered = jnp.sort(keyed)
    first = jnp.searchsorted(ordered, keyed, side="left")  # entries below this one
    last = jnp.searchsorted(ordered, keyed, side="right") - 1  # ... and up to its last tie
    ranks = (first + last).astype(jnp.float32) / 2.0
    count = jnp.sum(valid_flat)
    shaped = ranks / jnp.maximum(count - 1, 1).astype(jnp.float32) - 0.5
    return jnp.where(valid_flat, shaped, 0.0).reshape(x.shape)


def finite_scores(x: jax.Array, valid: jax.Array | None = None) -> jax.Array:
    """``x`` with every non-finite entry replaced by the lowest finite valid score (0 if there is none)."""
    valid_x = _valid_mask(x, valid)
    finite = jnp.isfinite(x)
    lowest = jnp.min(jnp.where(finite & valid_x, x, jnp.inf))
    return jnp.where(finite, x, jnp.where(jnp.isfinite(lowest), lowest, 0.0))


def signed_difference_ranks(scores: jax.Array, valid: jax.Array | None = None) -> jax.Array:
    """Per pair, sign(d) times the rank of |d| among the pairs, scaled to (0, 1]: d = f(+) - f(-).

    A pair's weight depends only on how its two members compare, not on how
    hard its episodes were (ranks of all 2N scores let an easy pair outweigh a
    hard one), and not on the scores' scale. A tied pair weighs 0; tied |d|
    share their average rank. A score that is not finite counts as the lowest
    (``finite_scores``).
    """
    valid = jnp.ones(scores.shape[:1], bool) if valid is None else valid
    finite = finite_scores(scores, valid[:, None])
    difference = (finite[:, 0] - finite[:, 1]).astype(jnp.float32)
    size = jnp.where(valid, jnp.abs(difference), jnp.inf)  # pairs not valid rank last
    ordered = jnp.sort(size)
    first = jnp.searchsorted(ordered, size, side="left")
    last = jnp.searchsorted(ordered, size, side="right") - 1
    ranks = (first + last).astype(jnp.float32) / 2.0 + 1.0  # 1 .. n, ties averaged
    count = jnp.maximum(jnp.sum(valid), 1).astype(jnp.float32)
    return jnp.where(valid, jnp.sign(difference) * ranks / count, 0.0)


def pair_weights(scores: jax.Array, fitness_shaping: str, valid: jax.Array | None = None) -> jax.Array:
    """Per-pair weight w_i from scores [n, 2] (columns: +z, -z); 0 for pairs not ``valid``."""
    if fitness_shaping == "difference_ranks":
        return signed_difference_ranks(scores, valid)
    pair_valid = None if valid is None else valid[:, None]
    if fitness_shaping == "centered_ranks":
        shaped = centered_ranks(scores, pair_valid)
    else:
        shaped = finite_scores(scores, pair_valid)
    weights = shaped[:, 0] - shaped[:, 1]
    return weights if valid is None else jnp.where(valid, weights, 0.0)
