"""The baselines' networks: AlphaZero's policy-value net and MuZero's learned model.

Sizes follow PiZero's (one hidden layer of ``hidden_size``, abstract state of
``latent_size``), and the policy over concrete actions is the pointer head
PiZero's decoder uses (``agent.decoder.pointer_scores``): one small network
scores every action from its features and a shared context, so TSP's cities
and FLP's grid points are scored by what they are, not by their index.

Values and rewards are learned on the scale ``value_transform`` gives
(MuZero's h, scalar): 2048 scores in the thousands and TSP tours of 3 then
train with the same step size. The search sees them back on the score's
scale (``inverse_value_transform``).
"""

from __future__ import annotations

from typing import Callable, NamedTuple

import jax
import jax.numpy as jnp

from pizero_ray.agent import networks
from pizero_ray.agent.decoder import pointer_init, pointer_scores
from pizero_ray.config import Config
from pizero_ray.envs.base import EnvSpec, Observation

Params = networks.Params
NEGATIVE_LOGIT = -1e9  # an illegal action's prior: never chosen, nothing of the softmax


def value_transform(x: jax.Array, epsilon: float = 1e-3) -> jax.Array:
    """h(x) = sign(x) (sqrt(|x| + 1) - 1) + epsilon x (Pohlen et al. 2018; MuZero's value scaling)."""
    return jnp.sign(x) * (jnp.sqrt(jnp.abs(x) + 1.0) - 1.0) + epsilon * x


def inverse_value_transform(y: jax.Array, epsilon: float = 1e-3) -> jax.Array:
    """The exact inverse of ``value_transform``."""
    root = (jnp.sqrt(1.0 + 4.0 * epsilon * (jnp.abs(y) + 1.0 + epsilon)) - 1.0) / (2.0 * epsilon)
    return jnp.sign(y) * (root**2 - 1.0)


def masked_logits(logits: jax.Array, mask: jax.Array) -> jax.Array:
    return jnp.where(mask, logits, NEGATIVE_LOGIT)


class PolicyValue(NamedTuple):
    """AlphaZero's network: observation -> (policy logits [.., A], transformed value [..])."""

    init: Callable[[jax.Array], Params]
    apply: Callable[[Params, Observation], tuple[jax.Array, jax.Array]]


def make_policy_value(config: Config, spec: EnvSpec) -> PolicyValue:
    h = config.hidden_size

    def init(key: jax.Array) -> Params:
        kt, kv, kp = jax.random.split(key, 3)
        return {"torso": networks.dense_init(kt, spec.observation_size, h),
                "value": networks.dense_init(kv, h, 1),
                "policy": pointer_init(kp, h, spec.action_feature_size, h)}

    def apply(params: Params, observation: Observation):
        hidden = jnp.tanh(networks.dense(params["torso"], observation.vector))
        logits = pointer_scores(params["policy"], hidden, observation.action_features)
        return masked_logits(logits, observation.action_mask), networks.dense(params["value"], hidden)[..., 0]

    return PolicyValue(init, apply)


class Model(NamedTuple):
    """MuZero's learned model. Latents are [.., L]; ``action_features`` are the root's [.., A, F]."""

    init: Callable[[jax.Array], Params]
    # (params, observation) -> latent
    represent: Callable[[Params, Observation], jax.Array]
    # (params, latent, action [..], action_features) -> (transformed reward, next latent)
    dynamics: Callable[[Params, jax.Array, jax.Array, jax.Array], tuple[jax.Array, jax.Array]]
    # (params, latent, action_features) -> (policy logits [.., A], transformed value)
    predict: Callable[[Params, jax.Array, jax.Array], tuple[jax.Array, jax.Array]]


def make_model(config: Config, spec: EnvSpec) -> Model:
    h, latent, actions = config.hidden_size, config.latent_size, spec.num_actions
    action_input = actions + spec.action_feature_size

    def init(key: jax.Array) -> Params:
        keys = jax.random.split(key, 5)
        return {"representation": networks.mlp_init(keys[0], (spec.observation_size, h, latent)),
                "dynamics": networks.gru_init(keys[1], action_input, latent),
                "reward": networks.dense_init(keys[2], latent, 1),
                "value": networks.mlp_init(keys[3], (latent, h, 1)),
                "policy": pointer_init(keys[4], latent, spec.action_feature_size, h)}

    def represent(params: Params, observation: Observation) -> jax.Array:
        return jnp.tanh(networks.mlp(params["representation"], observation.vector))

    def dynamics(params: Params, latent: jax.Array, action: jax.Array, action_features: jax.Array):
        # The action is read as its index and as its features at the root (where the search started).
        taken = jnp.take_along_axis(action_features, action[..., None, None].astype(jnp.int32), axis=-2)[..., 0, :]
        x = jnp.concatenate([jax.nn.one_hot(action, actions), taken], axis=-1)
        next_latent = networks.gru(params["dynamics"], latent, x)
        return networks.dense(params["reward"], next_latent)[..., 0], next_latent

    def predict(params: Params, latent: jax.Array, action_features: jax.Array):
        value = networks.mlp(params["value"], latent)[..., 0]
        return pointer_scores(params["policy"], latent, action_features), value

    return Model(init, represent, dynamics, predict)
