"""The project's one way into mctx: a search policy, its hyperparameters bound once.

PiZero's planner (over the learned abstract model) and the baselines' searches
(AlphaZero over the simulator, MuZero over its model) differ in their root and
recurrent functions, not in how they call mctx: ``make_policy`` binds the
choice (PUCT as in AlphaZero/MuZero, or Gumbel MuZero), the search budget and
the root noise, and returns ``(params, key, root, recurrent_fn,
invalid_actions) -> mctx.PolicyOutput``.

How the action is taken from the search is the caller's choice too: sampled
from the visit counts at a temperature (mctx's own muzero_policy; the
baselines), or the most visited action, first index on ties (PiZero). With
no root noise the latter skips muzero_policy's Dirichlet draw, weighed by 0
but still sampled, for the same tree (``most_visited_without_root_noise``).
"""

from __future__ import annotations

import functools
from typing import Callable

import jax
import jax.numpy as jnp
import mctx

# (params, key, root, recurrent_fn, invalid_actions [B, A] bool or None) -> mctx.PolicyOutput
SearchPolicy = Callable[..., mctx.PolicyOutput]

MAX_CONSIDERED_ACTIONS = 16  # Gumbel MuZero's default, where a caller does not narrow it


def unrolled_fori_loop(lower: int, upper: int, body, init):
    """``jax.lax.fori_loop``'s contract as straight-line code: ``body`` traced once per index, no while loop.

    mctx takes the loop over simulations as ``loop_fn``. Unrolled, the program
    has no loop around the simulations (each one's walk down and backup stay
    mctx's while loops): on a GPU that is one condition copied to the host less
    per simulation, for a compile that grows with the budget. The index is an
    int32 as fori_loop's is, so the tree is the same.
    """
    value = init
    for index in range(lower, upper):
        value = body(jnp.int32(index), value)
    return value


LOOP_FNS = {"fori": jax.lax.fori_loop, "unrolled": unrolled_fori_loop}


def make_policy(planner: str, num_simulations: int, root_noise: float, *, pb_c_init: float = 1.25,
                pb_c_base: float = 19652.0, most_visited: bool = False, temperature: float = 1.0,
                max_considered_actions: int = MAX_CONSIDERED_ACTIONS, simulation_loop: str = "fori") -> SearchPolicy:
    """mctx's policy for ``planner`` ("muzero": PUCT, root noise the Dirichlet fraction; "gumbel": Gumbel MuZero,
    root noise the Gumbel scale), bound to its hyperparameters.

    ``most_visited``: the action is the most visited one (PUCT), else it is
    drawn from the visit counts at ``temperature``. Gumbel MuZero's action is
    always its own (sequential halving's choice). ``simulation_loop`` ("fori"
    or "unrolled", ``LOOP_FNS``) is how the simulations are looped over.
    """
    loop_fn = LOOP_FNS[simulation_loop]
    if planner == "gumbel":
        policy = functools.partial(mctx.gumbel_muzero_policy, num_simulations=num_simulations,
                                   gumbel_scale=root_noise, max_num_considered_actions=max_considered_actions,
                                   loop_fn=loop_fn)
        return _with_invalid_actions(policy)
    if most_visited and root_noise == 0:
        return functools.partial(most_visited_without_root_noise, num_simulations=num_simulations,
                                 pb_c_init=pb_c_init, pb_c_base=pb_c_base, loop_fn=loop_fn)
    policy = _with_invalid_actions(functools.partial(
        mctx.muzero_policy, num_simulations=num_simulations, dirichlet_fraction=root_noise, temperature=temperature,
        pb_c_init=pb_c_init, pb_c_base=pb_c_base, loop_fn=loop_fn))
    return _taking_most_visited(policy) if most_visited else policy


def _with_invalid_actions(policy) -> SearchPolicy:
    def search(params, key, root, recurrent_fn, invalid_actions=None):
        return policy(params, key, root, recurrent_fn, invalid_actions=invalid_actions)

    return search


def _taking_most_visited(policy: SearchPolicy) -> SearchPolicy:
    def search(params, key, root, recurrent_fn, invalid_actions=None):
        output = policy(params, key, root, recurrent_fn, invalid_actions)
        return output.replace(action=jnp.argmax(output.action_weights, axis=-1).astype(jnp.int32))

    return search


def most_visited_without_root_noise(params, key, root: mctx.RootFnOutput, recurrent_fn, invalid_actions=None, *,
                                    num_simulations: int, pb_c_init: float, pb_c_base: float,
                                    loop_fn=jax.lax.fori_loop) -> mctx.PolicyOutput:
    """Exactly ``mctx.muzero_policy``'s tree with a Dirichlet fraction of 0, without sampling the noise; the most
    visited action.

    muzero_policy draws Dirichlet noise (gamma rejection sampling) even when it
    weighs it by 0; at our batch sizes that costs about 5% of a rollout. Same
    key split and the same prior logits (log of the softmax), so the same tree.
    """
    _, _, search_key = jax.random.split(key, 3)
    prior_logits = jnp.log(jnp.maximum(jax.nn.softmax(root.prior_logits), jnp.finfo(root.prior_logits.dtype).tiny))
    if invalid_actions is not None:  # as muzero_policy masks them: a finite floor, no NaN when all are invalid
        prior_logits = prior_logits - jnp.max(prior_logits, axis=-1, keepdims=True)
        prior_logits = jnp.where(invalid_actions, jnp.finfo(prior_logits.dtype).min, prior_logits)
    selection = functools.partial(
        mctx.muzero_action_selection, pb_c_init=pb_c_init, pb_c_base=pb_c_base,
        qtransform=mctx.qtransform_by_parent_and_siblings,
    )
    tree = mctx.search(
        params=params, rng_key=search_key, root=root.replace(prior_logits=prior_logits), recurrent_fn=recurrent_fn,
        root_action_selection_fn=functools.partial(selection, depth=0), interior_action_selection_fn=selection,
        num_simulations=num_simulations, invalid_actions=invalid_actions, loop_fn=loop_fn,
    )
    visit_probs = tree.summary().visit_probs
    action = jnp.argmax(visit_probs, axis=-1).astype(jnp.int32)
    return mctx.PolicyOutput(action=action, action_weights=visit_probs, search_tree=tree)
