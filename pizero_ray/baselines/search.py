"""The baselines' searches, with mctx: over the true simulator (AlphaZero) or a learned model (MuZero).

AlphaZero's recurrent function is the environment's own ``step`` on the
environment state. An episode's end is absorbing: the transition that ends
it has discount 0 (nothing below it is backed up) and value 0, and any step
taken from an ended state leaves it unchanged with reward 0 and discount 0,
so no value is ever backed up past the end of an episode. Illegal actions are
masked at the root (``invalid_actions``) and in the interior (very negative
prior logits). Where the environment keeps randomness for its future in its
state (2048's tiles, Pac-Man's ghosts), each search by default steps a copy
whose randomness is redrawn (``with_sampled_futures``): the tree is one
sampled future, as a simulator that cannot see the game's own draws would
give. ``--simulator-randomness foreseen`` searches the true future instead.

MuZero's recurrent function is the learned dynamics and prediction; the
model itself learns, from its unroll targets, that past an episode's end
rewards and values are 0. Only the root's legal actions are known.

``make_search(config, root_fn, recurrent_fn, training)`` binds the mctx policy
(PUCT as in AlphaZero/MuZero, or Gumbel MuZero) and its hyperparameters:
in self-play (``training``) the root gets Dirichlet noise (fraction
``root_noise``) and the action is drawn from the visit counts; in evaluation
the most visited action is taken, without noise (Gumbel: scale ``root_noise``
in self-play, 0 in evaluation).
"""

from __future__ import annotations

import functools
from typing import Callable, NamedTuple

import jax
import jax.numpy as jnp
import mctx

from pizero_ray.agent import mcts
from pizero_ray.baselines.networks import Model, PolicyValue, inverse_value_transform
from pizero_ray.config import Config
from pizero_ray.envs.base import Environment, Observation, where_done


class SimulatorNode(NamedTuple):
    """AlphaZero's embedding: the environment state and whether its episode has ended."""

    state: object  # the environment's state pytree, leading dimension B
    done: jax.Array  # [B] bool


def simulator_root(net: PolicyValue, params, observation: Observation, state) -> mctx.RootFnOutput:
    logits, value = net.apply(params, observation)
    done = jnp.zeros(value.shape, bool)
    return mctx.RootFnOutput(prior_logits=logits, value=inverse_value_transform(value),
                             embedding=SimulatorNode(state, done))


def simulator_recurrent_fn(env: Environment, net: PolicyValue):
    """mctx recurrent function over the true environment."""

    def recurrent_fn(params, key, action, node: SimulatorNode):
        del key  # the environment's randomness (2048's tiles) lives in its state: with_sampled_futures redraws it
        stepped, observation, reward, step_done = jax.vmap(env.step)(node.state, action)
        logits, value = net.apply(params, observation)
        ended = node.done | step_done
        out = mctx.RecurrentFnOutput(
            reward=jnp.where(node.done, 0.0, reward),
            discount=jnp.where(ended, 0.0, 1.0),
            prior_logits=logits,  # already masked by the new state's legal actions
            value=jnp.where(ended, 0.0, inverse_value_transform(value)))
        return out, SimulatorNode(where_done(node.done, node.state, stepped), ended)

    return recurrent_fn


class ModelNode(NamedTuple):
    """MuZero's embedding: the latent state and the root's action features (what the policy head scores)."""

    latent: jax.Array  # [B, L]
    action_features: jax.Array  # [B, A, F]


def model_root(model: Model, params, observation: Observation, state) -> mctx.RootFnOutput:
    del state  # MuZero never sees the simulator
    latent = model.represent(params, observation)
    logits, value = model.predict(params, latent, observation.action_features)
    return mctx.RootFnOutput(prior_logits=logits, value=inverse_value_transform(value),
                             embedding=ModelNode(latent, observation.action_features))


def model_recurrent_fn(model: Model):
    """mctx recurrent function over the learned model (discount 1: the model learns the absorbing end)."""

    def recurrent_fn(params, key, action, node: ModelNode):
        del key
        reward, latent = model.dynamics(params, node.latent, action, node.action_features)
        logits, value = model.predict(params, latent, node.action_features)
        out = mctx.RecurrentFnOutput(reward=inverse_value_transform(reward), discount=jnp.ones_like(reward),
                                     prior_logits=logits, value=inverse_value_transform(value))
        return out, ModelNode(latent, node.action_features)

    return recurrent_fn


# (params, observation [B], env state [B], key) -> mctx.PolicyOutput
Search = Callable[[object, Observation, object, jax.Array], mctx.PolicyOutput]


def make_search(config: Config, root_fn, recurrent_fn, training: bool) -> Search:
    """The configured mctx search over ``recurrent_fn``, its hyperparameters bound (``agent.mcts``)."""
    policy = mcts.make_policy(config.planner, config.num_simulations, config.root_noise if training else 0.0,
                              pb_c_init=config.pb_c_init, pb_c_base=config.pb_c_base,
                              temperature=1.0 if training else 0.0, simulation_loop=config.simulation_loop)

    def search(params, observation: Observation, state, key: jax.Array) -> mctx.PolicyOutput:
        root = root_fn(params, observation, state)
        return policy(params, key, root, recurrent_fn, invalid_actions=~observation.action_mask)

    return search


RESEED_STREAM = 1  # the search key's fold-in for the redrawn futures; mctx itself gets the key unchanged


def with_sampled_futures(search: Search, reseed: Callable) -> Search:
    """``search`` over copies of the states whose future randomness is redrawn from the search's key."""

    def searched(params, observation: Observation, state, key: jax.Array) -> mctx.PolicyOutput:
        batch = observation.action_mask.shape[0]
        keys = jax.random.split(jax.random.fold_in(key, RESEED_STREAM), batch)
        return search(params, observation, jax.vmap(reseed)(state, keys), key)

    return searched


def make_method_search(config: Config, env: Environment, training: bool) -> tuple[Callable, Search]:
    """(network init, search) for ``config.method``: alphazero over ``env``, muzero over its model."""
    from pizero_ray.baselines.networks import make_model, make_policy_value

    if config.method == "alphazero":
        net = make_policy_value(config, env.spec)
        root_fn, recurrent_fn = functools.partial(simulator_root, net), simulator_recurrent_fn(env, net)
    else:
        net = make_model(config, env.spec)
        root_fn, recurrent_fn = functools.partial(model_root, net), model_recurrent_fn(net)
    search = make_search(config, root_fn, recurrent_fn, training)
    if config.method == "alphazero" and env.reseed is not None and config.simulator_randomness == "sampled":
        search = with_sampled_futures(search, env.reseed)
    return net.init, search
