"""The PiZero agent: encoder, planner over a learned abstract model, decoder, memory.

One step, for a batch of B episodes:
  latent = encoder(observation, memory)               (the abstract state)
  search = MCTS(latent) over dynamics and prediction  (mctx; skipped with planner none)
  action = decoder(search result, action features)    (concrete action)
  memory = GRU(memory, observation and taken action)

All parameters form one pytree (``init_params``); ``act`` is pure and jittable.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp

from envs.base import EnvSpec, Observation
from pizero_ray.agent import decoder, networks, planner
from pizero_ray.agent.planner import PlanResult
from pizero_ray.config import Config


class StepInfo(NamedTuple):
    latent: jax.Array  # [B, L]
    plan: PlanResult  # zeros when there is no planner


def init_params(key: jax.Array, config: Config, spec: EnvSpec) -> networks.Params:
    o, m, h = spec.observation_size, config.memory_size, config.hidden_size
    latent, k = config.latent_size, config.num_abstract_actions
    keys = jax.random.split(key, 6)
    params = {
        "encoder": networks.mlp_init(keys[0], (o + m, h, latent)),
        "memory": networks.gru_init(keys[1], o + spec.action_input_size, m),
        "decoder": decoder.init(keys[2], config, spec),
    }
    if config.planner != "none":
        # With chance nodes the dynamics GRU reads the abstract chance outcome;
        # the abstract action first leads to an afterstate.
        dynamics_input = config.chance_outcomes if config.chance_outcomes > 0 else k
        params["dynamics"] = networks.gru_init(keys[3], dynamics_input, latent)
        params["reward"] = networks.dense_init(keys[4], latent, 1)
        params["prediction"] = networks.mlp_init(keys[5], (latent, h, 1 + k))
        if config.chance_outcomes > 0:
            after_keys = jax.random.split(jax.random.fold_in(key, 1), 2)
            params["afterstate"] = networks.gru_init(after_keys[0], k, latent)
            params["afterstate_prediction"] = networks.mlp_init(after_keys[1], (latent, h, 1 + config.chance_outcomes))
    return params


def initial_memory(config: Config, batch: int) -> jax.Array:
    return jnp.zeros((batch, config.memory_size), jnp.float32)


def encode(params: networks.Params, observation: Observation, memory: jax.Array) -> jax.Array:
    x = jnp.concatenate([observation.vector, memory], axis=-1)
    return jnp.tanh(networks.mlp(params["encoder"], x))  # same range as the dynamics GRU's states


def act(
    params: networks.Params,
    config: Config,
    spec: EnvSpec,
    memory: jax.Array,
    observation: Observation,
    key: jax.Array,
) -> tuple[jax.Array, jax.Array, StepInfo]:
    """Chooses actions for a batch of episodes; returns (action, new memory, info)."""
    plan_key, action_key = jax.random.split(key)
    latent = encode(params, observation, memory)
    batch = latent.shape[0]
    if config.planner == "none":
        k = config.num_abstract_actions
        search = PlanResult(jnp.zeros((batch,), jnp.int32), jnp.zeros((batch, k)), jnp.zeros((batch,)))
    else:
        search = planner.plan(params, config, latent, plan_key)
    ctx = decoder.context(config, latent, search)
    if spec.discrete:
        scores = decoder.action_scores(params["decoder"], config, ctx, observation.action_features)
        action = decoder.select_discrete(config, scores, observation.action_mask, action_key)
        taken = jnp.take_along_axis(observation.action_features, action[:, None, None], axis=1)[:, 0]
    else:
        action = decoder.continuous_action(params["decoder"], config, spec, ctx, action_key)
        taken = action
    memory_input = jnp.concatenate([observation.vector, taken], axis=-1)
    memory = networks.gru(params["memory"], memory, memory_input)
    return action, memory, StepInfo(latent, search)
