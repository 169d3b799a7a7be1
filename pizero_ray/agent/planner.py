"""MCTS over the learned abstract model, with DeepMind's mctx.

The abstract model is never fitted to the environment: its states, rewards
and values are whatever makes the whole agent score well under ES.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import mctx

from pizero_ray.agent import networks
from pizero_ray.config import Config


class PlanResult(NamedTuple):
    abstract_action: jax.Array  # [B] int32: the search's choice
    visit_probs: jax.Array  # [B, k]: the search's action distribution
    root_value: jax.Array  # [B]: the search's value estimate at the root


def predict(params: networks.Params, latent: jax.Array) -> tuple[jax.Array, jax.Array]:
    """Prediction function: abstract value [B] and logits over abstract actions [B, k]."""
    out = networks.mlp(params["prediction"], latent)
    return out[..., 0], out[..., 1:]


def dynamics(params: networks.Params, latent: jax.Array, abstract_action: jax.Array, k: int):
    """Dynamics GRU: one-hot abstract action in, abstract reward and next state out."""
    next_latent = networks.gru(params["dynamics"], latent, jax.nn.one_hot(abstract_action, k))
    reward = networks.dense(params["reward"], next_latent)[..., 0]
    return reward, next_latent


def afterstate(params: networks.Params, latent: jax.Array, abstract_action: jax.Array, k: int):
    """With chance nodes: the abstract action leads to an afterstate, its value and chance logits."""
    after = networks.gru(params["afterstate"], latent, jax.nn.one_hot(abstract_action, k))
    out = networks.mlp(params["afterstate_prediction"], after)
    return after, out[..., 0], out[..., 1:]


def plan(params: networks.Params, config: Config, latent: jax.Array, key: jax.Array) -> PlanResult:
    """Runs the configured search from a batch of abstract states [B, L]."""
    k = config.num_abstract_actions
    value, logits = predict(params, latent)
    root = mctx.RootFnOutput(prior_logits=logits, value=value, embedding=latent)
    if config.chance_outcomes > 0:
        return _plan_with_chance(params, config, root, key)

    def recurrent_fn(params, rng, action, embedding):
        del rng
        reward, next_latent = dynamics(params, embedding, action, k)
        next_value, next_logits = predict(params, next_latent)
        discount = jnp.full_like(reward, config.abstract_discount)
        output = mctx.RecurrentFnOutput(reward=reward, discount=discount, prior_logits=next_logits, value=next_value)
        return output, next_latent

    if config.planner == "muzero" and config.root_noise == 0:
        summary = _muzero_search_without_root_noise(params, config, root, recurrent_fn, key).summary()
        abstract_action = jnp.argmax(summary.visit_probs, axis=-1).astype(jnp.int32)
        return PlanResult(abstract_action, summary.visit_probs, summary.value)
    if config.planner == "muzero":
        output = mctx.muzero_policy(
            params, key, root, recurrent_fn, config.num_simulations,
            dirichlet_fraction=config.root_noise,
            pb_c_init=config.pb_c_init, pb_c_base=config.pb_c_base,
        )
        # mctx samples its action from the visit counts; PiZero acts on the
        # most visited abstract action (first index on ties) so that, with no
        # root noise, the agent is a deterministic function of its parameters.
        abstract_action = jnp.argmax(output.action_weights, axis=-1)
    elif config.planner == "gumbel":
        output = mctx.gumbel_muzero_policy(
            params, key, root, recurrent_fn, config.num_simulations,
            max_num_considered_actions=k, gumbel_scale=config.root_noise,
        )
        abstract_action = output.action
    else:
        raise ValueError(f"plan() needs a search planner, got {config.planner!r}")
    root_value = output.search_tree.summary().value
    return PlanResult(abstract_action.astype(jnp.int32), output.action_weights, root_value)


def _muzero_search_without_root_noise(params, config: Config, root: mctx.RootFnOutput, recurrent_fn, key):
    """Exactly ``mctx.muzero_policy``'s tree with a Dirichlet fraction of 0, without sampling the noise.

    muzero_policy draws Dirichlet noise (gamma rejection sampling) even when it
    weighs it by 0; at our batch sizes that costs about 5% of a rollout. Same
    key split and the same prior logits (log of the softmax), so the same tree.
    """
    _, _, search_key = jax.random.split(key, 3)
    prior_logits = jnp.log(jnp.maximum(jax.nn.softmax(root.prior_logits), jnp.finfo(root.prior_logits.dtype).tiny))
    selection = functools.partial(
        mctx.muzero_action_selection, pb_c_init=config.pb_c_init, pb_c_base=config.pb_c_base,
        qtransform=mctx.qtransform_by_parent_and_siblings,
    )
    return mctx.search(
        params=params, rng_key=search_key, root=root.replace(prior_logits=prior_logits), recurrent_fn=recurrent_fn,
        root_action_selection_fn=functools.partial(selection, depth=0), interior_action_selection_fn=selection,
        num_simulations=config.num_simulations,
    )


def _plan_with_chance(params: networks.Params, config: Config, root: mctx.RootFnOutput, key: jax.Array) -> PlanResult:
    """Stochastic MuZero search: abstract action -> afterstate -> abstract chance outcome -> state.

    The C chance outcomes are as invented as everything else in the model: ES
    decides what, if anything, they stand for (in 2048, where the tile appears).
    """
    k, c = config.num_abstract_actions, config.chance_outcomes

    def decision_fn(params, rng, action, embedding):
        del rng
        after, after_value, chance_logits = afterstate(params, embedding, action, k)
        return mctx.DecisionRecurrentFnOutput(chance_logits=chance_logits, afterstate_value=after_value), after

    def chance_fn(params, rng, outcome, after):
        del rng
        reward, next_latent = dynamics(params, after, outcome, c)
        next_value, next_logits = predict(params, next_latent)
        output = mctx.ChanceRecurrentFnOutput(
            action_logits=next_logits, value=next_value, reward=reward,
            discount=jnp.full_like(reward, config.abstract_discount),
        )
        return output, next_latent

    output = mctx.stochastic_muzero_policy(
        params, key, root, decision_fn, chance_fn, config.num_simulations,
        dirichlet_fraction=config.root_noise, pb_c_init=config.pb_c_init, pb_c_base=config.pb_c_base,
    )
    abstract_action = jnp.argmax(output.action_weights, axis=-1)
    return PlanResult(abstract_action.astype(jnp.int32), output.action_weights, output.search_tree.summary().value)
