"""The baselines' losses on a replay ``Batch``; values and rewards regress on the transformed scale.

AlphaZero: cross-entropy of the network's policy to the search's visit
distribution, plus squared error of its value to the Monte Carlo return.

MuZero: the planning loss. From the sampled position the model is unrolled
``K`` steps along the actions actually taken; at every step k = 0..K its
policy and value are held to the targets at position t + k, and at every
step k >= 1 its reward to the reward of action t + k - 1. Past the episode's
end the targets are absorbing (value and reward 0, no policy term). As in
MuZero, each step's gradient into the latent is halved and the loss is
averaged over the unroll.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

from pizero_ray.baselines.networks import Model, PolicyValue, value_transform
from pizero_ray.baselines.replay import Batch


def _cross_entropy(target: jax.Array, logits: jax.Array) -> jax.Array:
    log_probs = jax.nn.log_softmax(logits, axis=-1)
    return -jnp.sum(jnp.where(target > 0, target * log_probs, 0.0), axis=-1)


def scale_gradient(x: jax.Array, scale: float) -> jax.Array:
    """``x`` forward; its gradient times ``scale`` backward."""
    return x * scale + jax.lax.stop_gradient(x) * (1.0 - scale)


def alphazero_loss(net: PolicyValue, params, batch: Batch) -> tuple[jax.Array, dict]:
    logits, value = net.apply(params, batch.observation)
    policy_loss = jnp.mean(_cross_entropy(batch.policy[:, 0], logits))
    value_loss = jnp.mean((value - value_transform(batch.value[:, 0])) ** 2)
    return policy_loss + value_loss, {"policy_loss": policy_loss, "value_loss": value_loss}


def muzero_loss(model: Model, params, batch: Batch) -> tuple[jax.Array, dict]:
    features = batch.observation.action_features
    latent = model.represent(params, batch.observation)
    policy_terms, value_terms, reward_terms = [], [], []
    for k in range(batch.policy.shape[1]):
        if k > 0:
            reward, latent = model.dynamics(params, latent, batch.actions[:, k - 1], features)
            reward_terms.append((reward - value_transform(batch.reward[:, k - 1])) ** 2)
            latent = scale_gradient(latent, 0.5)
        logits, value = model.predict(params, latent, features)
        policy_terms.append(jnp.where(batch.policy_valid[:, k], _cross_entropy(batch.policy[:, k], logits), 0.0))
        value_terms.append((value - value_transform(batch.value[:, k])) ** 2)
    steps = len(policy_terms)
    policy_loss = jnp.mean(sum(policy_terms)) / steps
    value_loss = jnp.mean(sum(value_terms)) / steps
    reward_loss = jnp.mean(sum(reward_terms)) / steps if reward_terms else jnp.float32(0.0)
    total = policy_loss + value_loss + reward_loss
    return total, {"policy_loss": policy_loss, "value_loss": value_loss, "reward_loss": reward_loss}
