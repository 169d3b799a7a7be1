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

from pizero_ray.agent import decoder, networks, planner
from pizero_ray.agent.planner import PlanResult
from pizero_ray.config import PLAN_ABLATIONS, Config
from pizero_ray.envs.base import EnvSpec, Observation


class StepInfo(NamedTuple):
    latent: jax.Array  # [B, L]
    plan: PlanResult  # zeros when there is no planner
    # [B] bool, with ``make_agent(watch=...)``: the action the decoder would take from the ablated plan differs
    plan_changed: jax.Array | None = None


def ablate_plan(search: PlanResult, ablation: str | None) -> PlanResult:
    """``search`` as the decoder reads it under ``ablation`` (one of PLAN_ABLATIONS, or None: as it is)."""
    if ablation is None:
        return search
    if ablation == "shuffled":
        return jax.tree.map(lambda x: jnp.roll(x, 1, axis=0), search)
    if ablation == "zeroed":
        return jax.tree.map(jnp.zeros_like, search)
    raise ValueError(f"unknown plan ablation {ablation!r} (choose from {', '.join(PLAN_ABLATIONS)})")


class Agent(NamedTuple):
    init: Callable[[jax.Array], networks.Params]  # key -> parameters
    initial_memory: Callable[[int], jax.Array]  # batch size -> memory [B, M]
    # (params, memory [B, M], observation, key, env_state=None) -> (action, new memory, StepInfo). The episode
    # hands every agent the environment's state; only one that plans with the simulator (AlphaZero) reads it.
    act: Callable[..., tuple[jax.Array, jax.Array, StepInfo | None]]


def encode(params: networks.Params, observation: Observation, memory: jax.Array) -> jax.Array:
    x = jnp.concatenate([observation.vector, memory], axis=-1)
    return jnp.tanh(networks.mlp(params["encoder"], x))  # same range as the dynamics GRU's states


def make_agent(config: Config, spec: EnvSpec, plan_ablation: str | None = None, watch: str | None = None) -> Agent:
    """The agent of ``config``. ``plan_ablation``: its decoder reads the ablated plan (``ablate_plan``) instead of
    the search's. ``watch``: it acts on its own plan, and each step also says whether the ablated one would have
    changed its action (``StepInfo.plan_changed``): what the plan is worth, measured along its own episodes."""
    if config.planner == "none" and (plan_ablation or watch):
        raise ValueError("an agent without a planner has no plan to ablate")
    for name in (plan_ablation, watch):
        if name is not None and name not in PLAN_ABLATIONS:
            raise ValueError(f"unknown plan ablation {name!r} (choose from {', '.join(PLAN_ABLATIONS)})")
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
        action, taken = decode.act(params["decoder"], latent, ablate_plan(search, plan_ablation), observation,
                                   action_key)
        changed = None
        if watch is not None:
            other, _ = decode.act(params["decoder"], latent, ablate_plan(search, watch), observation, action_key)
            changed = jnp.any((other != action).reshape(action.shape[0], -1), axis=-1)
        memory = networks.gru(params["memory"], memory, jnp.concatenate([observation.vector, taken], axis=-1))
        return action, memory, StepInfo(latent, search, changed)

    return Agent(init, initial_memory, act)


def without_memory(agent: Agent) -> Agent:
    """The same agent with its memory held at the initial zeros: the ablation that tells what the memory is
    worth (on partially observed Pac-Man, say). The same parameters play; only what they remember is gone."""

    def act(params: networks.Params, memory: jax.Array, observation: Observation, key: jax.Array, env_state=None):
        action, _, info = agent.act(params, memory, observation, key, env_state)
        return action, memory, info  # memory stays what initial_memory gave

    return agent._replace(act=act)
