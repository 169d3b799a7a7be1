"""The decoder: from the search result to a concrete action.

Discrete actions are scored pointer-style by default: one small network is
applied to every candidate action's features together with a context vector
from the search (abstract state, chosen abstract action, visit distribution,
root value; which of these is configurable). On TSP this structure is what lets
ES learn at all: a flat output layer over action indices barely moves (see
docs/tsp.md). The ``flat`` decoder is kept for that comparison.

Continuous actions come from an MLP squashed into the action bounds.

``make_decoder(config, spec)`` binds the choices once and returns
``Decoder(init, act)``.
"""

from __future__ import annotations

import functools
from typing import Callable, NamedTuple

import jax
import jax.numpy as jnp

from pizero_ray.agent import networks
from pizero_ray.agent.planner import PlanResult
from pizero_ray.config import Config
from pizero_ray.envs.base import EnvSpec, Observation


class Decoder(NamedTuple):
    init: Callable[[jax.Array], networks.Params]  # key -> the decoder's parameters
    # (params, latent [B, L], plan, observation, key) -> (action [B] or [B, d], the taken action's features)
    act: Callable[..., tuple[jax.Array, jax.Array]]


def context_size(inputs: tuple[str, ...], latent_size: int, num_abstract_actions: int) -> int:
    sizes = {"state": latent_size, "action": num_abstract_actions, "visits": num_abstract_actions, "value": 1,
             "qvalues": num_abstract_actions}
    return sum(sizes[name] for name in inputs)


def context(latent: jax.Array, plan: PlanResult, *, inputs: tuple[str, ...], num_abstract_actions: int) -> jax.Array:
    """What the decoder reads: the chosen parts of (abstract state, abstract action, visits, root value, root
    children's Q-values)."""
    parts = {
        "state": lambda: latent,
        "action": lambda: jax.nn.one_hot(plan.abstract_action, num_abstract_actions),
        "visits": lambda: plan.visit_probs,
        "value": lambda: plan.root_value[..., None],
        "qvalues": lambda: plan.root_qvalues,
    }
    return jnp.concatenate([parts[name]() for name in inputs], axis=-1)


def pointer_init(key: jax.Array, context_size: int, feature_size: int, hidden_size: int) -> networks.Params:
    kf, kc, ko = jax.random.split(key, 3)
    # The first layer is split into a per-action part and a shared context
    # part so the context's product is computed once, not once per action.
    return {
        "features": networks.dense_init(kf, feature_size, hidden_size),
        "context": {"w": networks.dense_init(kc, context_size, hidden_size)["w"]},  # its bias is the features' bias
        "out": networks.dense_init(ko, hidden_size, 1),
    }


def pointer_scores(params: networks.Params, ctx: jax.Array, action_features: jax.Array) -> jax.Array:
    """Logits over discrete actions: [B, A] from ctx [B, C] and features [B, A, F], one network per action."""
    shared = networks.linear(ctx, params["context"]["w"])[..., None, :]
    hidden = networks.dense(params["features"], action_features) + shared
    return networks.dense(params["out"], jnp.tanh(hidden))[..., 0]


def flat_scores(params: networks.Params, ctx: jax.Array, action_features: jax.Array) -> jax.Array:
    """Logits over discrete actions from the context alone (an output per action index)."""
    del action_features
    return networks.mlp(params, ctx)


def select_discrete(scores: jax.Array, mask: jax.Array, key: jax.Array, *, sample: bool, noise: float) -> jax.Array:
    """Argmax over legal actions, or a Gumbel-perturbed argmax (sampling from softmax)."""
    if sample:
        scores = scores + noise * jax.random.gumbel(key, scores.shape)
    return jnp.argmax(jnp.where(mask, scores, -jnp.inf), axis=-1).astype(jnp.int32)


def squashed_action(params: networks.Params, ctx: jax.Array, key: jax.Array, *, sample: bool, noise: float,
                    low: float, high: float) -> jax.Array:
    """A point in [low, high]^d; with ``sample``, Gaussian latent noise before the squashing."""
    pre = networks.mlp(params, ctx)
    if sample:
        pre = pre + noise * jax.random.normal(key, pre.shape)
    return low + (high - low) * jax.nn.sigmoid(pre)


def make_decoder(config: Config, spec: EnvSpec) -> Decoder:
    inputs, k, h = config.effective_decoder_inputs, config.num_abstract_actions, config.hidden_size
    c = context_size(inputs, config.latent_size, k)
    read = functools.partial(context, inputs=inputs, num_abstract_actions=k)
    sample, noise = config.action_selection == "sample", config.action_noise

    if not spec.discrete:
        choose = functools.partial(squashed_action, sample=sample, noise=noise,
                                   low=spec.action_low, high=spec.action_high)

        def act_continuous(params, latent, plan, observation: Observation, key):
            action = choose(params, read(latent, plan), key)
            return action, action

        return Decoder(lambda key: networks.mlp_init(key, (c, h, spec.action_dim)), act_continuous)

    if config.decoder == "flat":
        init, scores = (lambda key: networks.mlp_init(key, (c, h, spec.num_actions))), flat_scores
    else:
        init, scores = functools.partial(pointer_init, context_size=c, feature_size=spec.action_feature_size,
                                         hidden_size=h), pointer_scores
    choose = functools.partial(select_discrete, sample=sample, noise=noise)

    def act_discrete(params, latent, plan, observation: Observation, key):
        logits = scores(params, read(latent, plan), observation.action_features)
        action = choose(logits, observation.action_mask, key)
        taken = jnp.take_along_axis(observation.action_features, action[:, None, None], axis=1)[:, 0]
        return action, taken

    return Decoder(init, act_discrete)
