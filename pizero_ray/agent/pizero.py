"""The PiZero agent: encoder, planner over a learned abstract model, decoder, memory.

One step, for a batch of B episodes:
  latent = encoder(observation, memory)               (the abstract state)
  search = MCTS(latent) over dynamics and prediction  (mctx; skipped with planner none)
  action = decoder(search result, action features)    (concrete action)
  memory = GRU(memory, observation and taken action)

``make_agent(config, spec)`` binds the configuration once and returns
``Agent(init, initial_memory, act)``: all parameters form one pytree
(``init``), and ``act`` is pure and jittable.
"""

from __future__ import annotations

from typing import Callable, NamedTuple

import jax
import jax.numpy as jnp

from envs.base import EnvSpec, Observation
from pizero_ray.agent import decoder, networks, planner
from pizero_ray.agent.planner import PlanResult
from pizero_ray.config import Config


class StepInfo(NamedTuple):
    latent: jax.Array  # [B, L]
    plan: PlanResult  # zeros when there is no planner


class Agent(NamedTuple):
    init: Callable[[jax.Array], networks.Params]  # key -> parameters
    initial_memory: Callable[[int], jax.Array]  # batch size -> memory [B, M]
    # (params, memory [B, M], observation, key, env_state=None) -> (action, new memory, StepInfo). The episode
    # hands every agent the environment's state; only one that plans with the simulator (AlphaZero) reads it.
    act: Callable[..., tuple[jax.Array, jax.Array, StepInfo | None]]


def encode(params: networks.Params, observation: Observation, memory: jax.Array) -> jax.Array:
    x = jnp.concatenate([observation.vector, memory], axis=-1)
    return jnp.tanh(networks.mlp(params["encoder"], x))  # same range as the dynamics GRU's states


def make_agent(config: Config, spec: EnvSpec) -> Agent:
    plan = planner.make_planner(config)
    decode = decoder.make_decoder(config, spec)
    memory_size = config.memory_size
    encoder_sizes = (spec.observation_size + memory_size, config.hidden_size, config.latent_size)

    def init(key: jax.Array) -> networks.Params:
        keys = jax.random.split(key, 6)  # 3-5 (and a fold of the key) are the abstract model's
        params = {
            "encoder": networks.mlp_init(keys[0], encoder_sizes),
            "memory": networks.gru_init(keys[1], spec.observation_size + spec.action_input_size, memory_size),
            "decoder": decode.init(keys[2]),
        }
        return {**params, **planner.init(key, config)}

    def initial_memory(batch: int) -> jax.Array:
        return jnp.zeros((batch, memory_size), jnp.float32)

    def act(params: networks.Params, memory: jax.Array, observation: Observation, key: jax.Array, env_state=None):
        """Chooses actions for a batch of episodes; returns (action, new memory, info). Never reads env_state."""
        del env_state
        plan_key, action_key = jax.random.split(key)
        latent = encode(params, observation, memory)
        search = plan(params, latent, plan_key)
        action, taken = decode.act(params["decoder"], latent, search, observation, action_key)
        memory = networks.gru(params["memory"], memory, jnp.concatenate([observation.vector, taken], axis=-1))
        return action, memory, StepInfo(latent, search)

    return Agent(init, initial_memory, act)


def without_memory(agent: Agent) -> Agent:
    """The same agent with its memory held at the initial zeros: the ablation that tells what the memory is
    worth (on partially observed Pac-Man, say). The same parameters play; only what they remember is gone."""

    def act(params: networks.Params, memory: jax.Array, observation: Observation, key: jax.Array, env_state=None):
        action, _, info = agent.act(params, memory, observation, key, env_state)
        return action, memory, info  # memory stays what initial_memory gave

    return agent._replace(act=act)
