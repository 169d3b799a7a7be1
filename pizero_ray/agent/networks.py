"""Tiny network building blocks as plain functions over parameter pytrees.

Parameters are dicts of float32 arrays so the whole agent is one pytree that
ES can flatten into a single vector. Every apply function accepts arbitrary
leading batch dimensions. With low-rank ES noise, a population member's weight
matrices are ``LowRankPerturbed`` (shared matrix plus its own rank-r factors)
and every layer goes through ``linear``, which never forms them.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

Params = dict


def dense_init(key: jax.Array, n_in: int, n_out: int, scale: float = 1.0) -> Params:
    # LeCun-normal weights: unit-scale activations, so a fixed ES sigma means
    # the same relative perturbation in every layer.
    w = jax.random.normal(key, (n_in, n_out), jnp.float32) * (scale / jnp.sqrt(n_in))
    return {"w": w, "b": jnp.zeros((n_out,), jnp.float32)}


class LowRankPerturbed(NamedTuple):
    """A weight matrix base + left.T @ right, never formed: one population member's view of a shared matrix."""

    base: jax.Array  # [n, m], shared by every member
    left: jax.Array  # [r, n], the member's noise factor (transposed) times its signed step
    right: jax.Array  # [r, m]


def linear(x: jax.Array, w) -> jax.Array:
    """x @ w for a plain matrix or a low-rank-perturbed one.

    Under vmap over members the shared x @ base becomes one large matrix
    product for the whole population; only the rank-r term is per member.
    """
    if isinstance(w, LowRankPerturbed):
        return x @ w.base + (x @ w.left.T) @ w.right
    return x @ w


def dense(params: Params, x: jax.Array) -> jax.Array:
    return linear(x, params["w"]) + params["b"]


def mlp_init(key: jax.Array, sizes: tuple[int, ...]) -> Params:
    keys = jax.random.split(key, len(sizes) - 1)
    return {f"layer{i}": dense_init(k, a, b) for i, (k, a, b) in enumerate(zip(keys, sizes[:-1], sizes[1:]))}


def mlp(params: Params, x: jax.Array) -> jax.Array:
    """tanh hidden layers, linear output."""
    n = len(params)
    for i in range(n):
        x = dense(params[f"layer{i}"], x)
        if i < n - 1:
            x = jnp.tanh(x)
    return x


def gru_init(key: jax.Array, input_size: int, hidden_size: int) -> Params:
    kx, kh = jax.random.split(key)
    return {
        "input": dense_init(kx, input_size, 3 * hidden_size),
        "hidden": dense_init(kh, hidden_size, 3 * hidden_size),
    }


def gru(params: Params, hidden: jax.Array, x: jax.Array) -> jax.Array:
    """One GRU step (Cho et al. 2014); returns the new hidden state."""
    gx = dense(params["input"], x)
    gh = dense(params["hidden"], hidden)
    xr, xz, xn = jnp.split(gx, 3, axis=-1)
    hr, hz, hn = jnp.split(gh, 3, axis=-1)
    reset = jax.nn.sigmoid(xr + hr)
    update = jax.nn.sigmoid(xz + hz)
    candidate = jnp.tanh(xn + reset * hn)
    return (1.0 - update) * candidate + update * hidden
