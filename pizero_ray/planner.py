"""MCTS over the learned abstract model, with DeepMind's mctx.

The abstract model is never fitted to the environment: its states, rewards
and values are whatever makes the whole agent score well under ES.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import mctx

from pizero_ray import networks
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


def plan(params: networks.Params, config: Config, latent: jax.Array, key: jax.Array) -> PlanResult:
    """Runs the configured search from a batch of abstract states [B, L]."""
    k = config.num_abstract_actions
    value, logits = predict(params, latent)
    root = mctx.RootFnOutput(prior_logits=logits, value=value, embedding=latent)

    def recurrent_fn(params, rng, action, embedding):
        del rng
        reward, next_latent = dynamics(params, embedding, action, k)
        next_value, next_logits = predict(params, next_latent)
        discount = jnp.full_like(reward, config.abstract_discount)
        output = mctx.RecurrentFnOutput(reward=reward, discount=discount, prior_logits=next_logits, value=next_value)
        return output, next_latent

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
