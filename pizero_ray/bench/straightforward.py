"""The straightforward rollout: the PiZero agent written the plain way, the baseline of the bench's speed-ups.

The same agent as the trainer's (encoder, memory and decoder from
``pizero_ray.agent``, the abstract model's ``predict`` and ``dynamics``), with
the same parameters: member 2i and 2i + 1 are theta + sigma z_i and
theta - sigma z_i, z_i pair i's full-rank Gaussian noise. Each member plays its
own episode under a plain ``lax.scan`` over the horizon, and every step's
search is a direct call of ``mctx.muzero_policy`` on a batch of one, the
member's own abstract state [1, L]. The population is ``jax.vmap`` of that
member function, jitted once, on one device.

None of the project's speed-ups: no search that skips muzero_policy's
Dirichlet draw (the planner's, ``agent.mcts``), no low-rank
noise, no loop that stops once every episode has ended (``pizero_ray.envs.base.play``,
as ``agent.episodes`` plays), no chunks dealt over devices, no noise handed
in from outside the rollout. It plays the trainer's game for the same keys: the
same instances (reset keys) and the same search and action keys, and a
Dirichlet weight of 0 leaves muzero_policy's tree the project's
(tests/agent/test_planner.py), so the scores are the trainer's rollout's
(tests/bench/test_straightforward.py checks it).
"""

from __future__ import annotations

import time

import jax
import jax.numpy as jnp
import mctx
import numpy as np

from pizero_ray.agent import decoder, networks, pizero, planner
from pizero_ray.agent.episodes import episode_reset_keys
from pizero_ray.agent.planner import PlanResult
from pizero_ray.bench.timing import CompiledRollout
from pizero_ray.config import Config
from pizero_ray.envs.base import Environment
from pizero_ray.es import noise as es_noise
from pizero_ray.es.population import FlatParams


def _check_supported(config: Config) -> None:
    """The straightforward rollout is the bench agent's: full-rank noise, the muzero planner, one episode."""
    unsupported = {"perturbation_rank": (config.perturbation_rank, 0), "planner": (config.planner, "muzero"),
                   "chance_outcomes": (config.chance_outcomes, 0),
                   # With several episodes the trainer's agent searches them as one batch with one key; a batch-1
                   # search per episode would draw other tie-breaks, another game.
                   "episodes_per_member": (config.episodes_per_member, 1)}
    wrong = [f"{name} {value!r} (needs {needed!r})" for name, (value, needed) in unsupported.items()
             if value != needed]
    if wrong:
        raise ValueError(f"the straightforward rollout does not support {', '.join(wrong)}")


def make_member_score(config: Config, env: Environment):
    """(params, episode_key) -> the member's score: one episode, a plain scan, a batch-1 mctx search per step."""
    _check_supported(config)
    decode = decoder.make_decoder(config, env.spec)
    recurrent_fn = planner._recurrent_fn(config.num_abstract_actions, config.abstract_discount)

    def search(params, latent, key) -> PlanResult:
        output = mctx.muzero_policy(
            params, key, planner._root(params, latent), recurrent_fn, config.num_simulations,
            dirichlet_fraction=config.root_noise, pb_c_init=config.pb_c_init, pb_c_base=config.pb_c_base)
        # The agent acts on the most visited abstract action (as the trainer's planner does), not mctx's sample.
        abstract_action = jnp.argmax(output.action_weights, axis=-1).astype(jnp.int32)
        return PlanResult(abstract_action, output.action_weights, output.search_tree.summary().value)

    def member_score(params, episode_key):
        # The keys of agent.episodes' run_episodes, for its one episode: the same instance, the same draws.
        state, observation = env.reset(episode_reset_keys(episode_key, 1)[0])
        act_key = jax.random.fold_in(episode_key, 1)

        def step(carry, t):
            state, observation, memory, done, score = carry
            plan_key, action_key = jax.random.split(jax.random.fold_in(act_key, t))
            batch = jax.tree.map(lambda x: x[None], observation)  # the agent's networks take a batch: of one
            latent = pizero.encode(params, batch, memory)
            action, taken = decode.act(params["decoder"], latent, search(params, latent, plan_key), batch, action_key)
            memory = networks.gru(params["memory"], memory, jnp.concatenate([batch.vector, taken], axis=-1))
            state, observation, reward, step_done = env.step(state, action[0])
            reward = jnp.where(done, 0.0, reward)  # nothing counts after the episode ended
            return (state, observation, memory, done | step_done, score + reward), None

        memory = jnp.zeros((1, config.memory_size), jnp.float32)
        carry = (state, observation, memory, jnp.bool_(False), jnp.float32(0.0))
        carry, _ = jax.lax.scan(step, carry, jnp.arange(env.spec.horizon))
        return carry[-1]

    return member_score


def make_population_scorer(config: Config, env: Environment, layout: FlatParams):
    """jit(theta [D], iteration_seed) -> scores [population, 2] (+z, -z), as the trainer's pairs are laid out."""
    member_score = make_member_score(config, env)
    pairs, sigma = config.population, config.sigma

    def score(theta, iteration_seed):
        key = es_noise.iteration_key(iteration_seed)
        indices = jnp.arange(pairs)
        noise = jax.vmap(es_noise.pair_noise, in_axes=(None, 0, None))(key, indices, layout.size)
        members = jnp.stack([theta + sigma * noise, theta - sigma * noise], axis=1).reshape(2 * pairs, -1)
        episode_keys = jnp.repeat(jax.vmap(es_noise.pair_episode_key, in_axes=(None, 0))(key, indices), 2, axis=0)
        scores = jax.vmap(lambda member, key: member_score(layout.unravel(member), key))(members, episode_keys)
        return scores.reshape(pairs, 2)

    return jax.jit(score)


def compile_straightforward(config: Config) -> CompiledRollout:
    """The straightforward rollout of ``config``'s population, compiled for the first device and warmed up."""
    from pizero_ray import envs
    from pizero_ray.es import population

    env = envs.make(config.env, **config.env_kwargs())
    theta, layout = population.flat_params(config, env)
    theta = jax.device_put(np.asarray(theta), jax.devices()[0])
    seed = jax.ShapeDtypeStruct((), jnp.uint32)
    started = time.perf_counter()
    scorer = make_population_scorer(config, env, layout).lower(theta, seed).compile()
    compile_s = time.perf_counter() - started

    def one_iteration(iteration_seed: int) -> float:
        started = time.perf_counter()
        np.asarray(scorer(theta, np.uint32(iteration_seed)))  # the scores on the host, as the project's rollout's
        return time.perf_counter() - started

    one_iteration(0)  # warm-up
    agent_steps = config.population * 2 * env.spec.horizon  # one episode per member, a scan to the horizon
    return CompiledRollout(config, one_iteration, compile_s, layout.size, agent_steps, devices=1)
