"""The decoder: from the search result to a concrete action.

Discrete actions are scored pointer-style by default: one small network is
applied to every candidate action's features together with a context vector
from the search (abstract state, chosen abstract action, visit distribution,
root value; which of these is configurable). On TSP this structure is what lets
ES learn at all: a flat output layer over action indices barely moves (see
docs/decoder.md). The ``flat`` decoder is kept for that comparison.

Continuous actions come from an MLP squashed into the action bounds.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from envs.base import EnvSpec
from pizero_ray.agent import networks
from pizero_ray.agent.planner import PlanResult
from pizero_ray.config import Config


def context_size(config: Config) -> int:
    sizes = {
        "state": config.latent_size,
        "action": config.num_abstract_actions,
        "visits": config.num_abstract_actions,
        "value": 1,
    }
    return sum(sizes[name] for name in config.effective_decoder_inputs)


def context(config: Config, latent: jax.Array, plan: PlanResult | None) -> jax.Array:
    parts = []
    for name in config.effective_decoder_inputs:
        if name == "state":
            parts.append(latent)
        elif name == "action":
            parts.append(jax.nn.one_hot(plan.abstract_action, config.num_abstract_actions))
        elif name == "visits":
            parts.append(plan.visit_probs)
        elif name == "value":
            parts.append(plan.root_value[..., None])
    return jnp.concatenate(parts, axis=-1)


def init(key: jax.Array, config: Config, spec: EnvSpec) -> networks.Params:
    c, h = context_size(config), config.hidden_size
    if not spec.discrete:
        return networks.mlp_init(key, (c, h, spec.action_dim))
    if config.decoder == "flat":
        return networks.mlp_init(key, (c, h, spec.num_actions))
    kf, kc, ko = jax.random.split(key, 3)
    # The first layer is split into a per-action part and a shared context
    # part so the context's product is computed once, not once per action.
    return {
        "features": networks.dense_init(kf, spec.action_feature_size, h),
        "context": {"w": networks.dense_init(kc, c, h)["w"]},  # its bias is the features' bias
        "out": networks.dense_init(ko, h, 1),
    }


def action_scores(params: networks.Params, config: Config, ctx: jax.Array, action_features: jax.Array) -> jax.Array:
    """Logits over discrete actions: [B, A] from ctx [B, C] and features [B, A, F]."""
    if config.decoder == "flat":
        return networks.mlp(params, ctx)
    shared = networks.linear(ctx, params["context"]["w"])[..., None, :]
    hidden = networks.dense(params["features"], action_features) + shared
    return networks.dense(params["out"], jnp.tanh(hidden))[..., 0]


def select_discrete(config: Config, scores: jax.Array, mask: jax.Array, key: jax.Array) -> jax.Array:
    """Argmax over legal actions, or a Gumbel-perturbed argmax (sampling from softmax)."""
    if config.action_selection == "sample":
        scores = scores + config.action_noise * jax.random.gumbel(key, scores.shape)
    return jnp.argmax(jnp.where(mask, scores, -jnp.inf), axis=-1).astype(jnp.int32)


def continuous_action(
    params: networks.Params, config: Config, spec: EnvSpec, ctx: jax.Array, key: jax.Array
) -> jax.Array:
    """A point in [low, high]^d; with ``sample``, Gaussian latent noise before the squashing."""
    pre = networks.mlp(params, ctx)
    if config.action_selection == "sample":
        pre = pre + config.action_noise * jax.random.normal(key, pre.shape)
    return spec.action_low + (spec.action_high - spec.action_low) * jax.nn.sigmoid(pre)
