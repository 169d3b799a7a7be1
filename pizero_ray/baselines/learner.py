"""A gradient-trained baseline, bound once: ``make_learner(config, env) -> Learner(init, iterate, agent)``.

One iteration, a single jitted function of the state: play
``selfplay_episodes`` episodes with the search (noise at the root, actions
drawn from the visit counts), add them to the replay buffer, then take
``updates_per_iteration`` Adam steps on batches of ``batch_size`` positions
sampled from it. Its randomness is a function of (seed, iteration) only, and
the state (``LearnerState``: flat parameters, Adam state and replay buffer)
is all it reads, so checkpoint and resume give the parameters an
uninterrupted run does.

The ``agent`` is the trained policy acting for evaluation: the same search
without noise, taking its most visited action (AlphaZero's search steps the
environment state the episode hands it; MuZero's never looks at it).
"""

from __future__ import annotations

import functools
from typing import Callable, NamedTuple

import jax
import jax.numpy as jnp
import optax
from jax.flatten_util import ravel_pytree

from pizero_ray.agent.pizero import Agent
from pizero_ray.baselines import losses, replay
from pizero_ray.baselines.networks import make_model, make_policy_value
from pizero_ray.baselines.search import make_method_search
from pizero_ray.config import Config
from pizero_ray.envs.base import Environment


class LearnerState(NamedTuple):
    theta: jax.Array  # flat float32 parameters (what checkpoints, eval and inspect read)
    adam: optax.OptState
    replay: replay.Replay  # the self-play episodes the updates sample from
    iteration: int

    @property
    def carried(self) -> dict:
        """What training continues from besides theta and the iteration (what a checkpoint keeps of it)."""
        return {"adam": self.adam, "replay": self.replay}

    def with_carried(self, carried: dict) -> LearnerState:
        return self._replace(adam=carried["adam"], replay=carried["replay"])


class LearnerStats(NamedTuple):
    mean_score: jax.Array  # the self-play episodes' mean score
    std_score: jax.Array
    max_score: jax.Array
    min_score: jax.Array
    loss: jax.Array  # the last update's, and its parts
    parts: dict


class Learner(NamedTuple):
    init: Callable[[], LearnerState]  # the state at iteration 0, parameters from config.seed
    iterate: Callable[[LearnerState], tuple[LearnerState, LearnerStats]]
    agent: Agent  # acts for evaluation, with the search and no noise
    size: int  # parameters
    unravel: Callable[[jax.Array], dict]


def _loss_fn(config: Config, env: Environment):
    if config.method == "alphazero":
        return functools.partial(losses.alphazero_loss, make_policy_value(config, env.spec)), 0
    return functools.partial(losses.muzero_loss, make_model(config, env.spec)), config.unroll_steps


def make_acting_agent(config: Config, env: Environment, init: Callable) -> Agent:
    """The trained policy as an ``Agent``: evaluation search, most visited action; no memory."""
    _, search = make_method_search(config, env, training=False)

    def act(params, memory, observation, key, env_state=None):
        return search(params, observation, env_state, key).action.astype(jnp.int32), memory, None

    return Agent(init, lambda batch: jnp.zeros((batch, 0), jnp.float32), act)


def make_learner(config: Config, env: Environment) -> Learner:
    init_params, search = make_method_search(config, env, training=True)
    theta0, unravel = ravel_pytree(init_params(jax.random.PRNGKey(config.seed)))
    loss_fn, unroll = _loss_fn(config, env)
    optimizer = optax.adamw(config.learning_rate, weight_decay=config.weight_decay)

    def init() -> LearnerState:
        template = jax.eval_shape(functools.partial(replay.play, search, unravel(theta0), env, num_episodes=1),
                                  jax.random.PRNGKey(0))
        empty = jax.tree_util.tree_map(lambda s: jnp.zeros(s.shape, s.dtype), template)
        return LearnerState(theta0, optimizer.init(unravel(theta0)), replay.replay_init(empty, config.replay_size), 0)

    def update(carry, key):
        params, adam, buffer = carry
        batch = replay.replay_sample(buffer, key, config.batch_size, unroll)
        (loss, parts), grads = jax.value_and_grad(lambda p: loss_fn(p, batch), has_aux=True)(params)
        updates, adam = optimizer.update(grads, adam, params)
        return (optax.apply_updates(params, updates), adam, buffer), (loss, parts)

    @jax.jit
    def step(theta, adam, buffer, iteration):
        key = jax.random.fold_in(jax.random.PRNGKey(config.seed), iteration)
        params = unravel(theta)
        episodes = replay.play(search, params, env, jax.random.fold_in(key, 0), config.selfplay_episodes)
        buffer = replay.replay_add(buffer, episodes)
        update_keys = jax.random.split(jax.random.fold_in(key, 1), config.updates_per_iteration)
        (params, adam, buffer), (loss, parts) = jax.lax.scan(update, (params, adam, buffer), update_keys)
        scores = episodes.reward.sum(axis=1)
        stats = LearnerStats(scores.mean(), scores.std(), scores.max(), scores.min(), loss[-1],
                             jax.tree_util.tree_map(lambda x: x[-1], parts))
        return ravel_pytree(params)[0], adam, buffer, stats

    def iterate(state: LearnerState) -> tuple[LearnerState, LearnerStats]:
        # Arrays restored from a checkpoint come with Orbax's sharding; placed as step's own outputs are, they
        # reuse its one compiled program instead of compiling another (twice: for them, then for its outputs).
        theta, adam, buffer = jax.device_put((state.theta, state.adam, state.replay), jax.devices()[0])
        theta, adam, buffer, stats = step(theta, adam, buffer, state.iteration)
        return LearnerState(theta, adam, buffer, state.iteration + 1), stats

    agent = make_acting_agent(config, env, init_params)
    return Learner(init, iterate, agent, int(theta0.size), unravel)
