"""MCTS over the learned abstract model, with DeepMind's mctx.

The abstract model is never fitted to the environment: its states, rewards
and values are whatever makes the whole agent score well under ES.

``make_planner(config)`` binds the search and its hyperparameters once, as
mctx's policies and optax's transformations are bound: the planner it
returns is a pure function (params, latent [B, L], key) -> PlanResult.
"""

from __future__ import annotations

import functools
from typing import Callable, NamedTuple

import jax
import jax.numpy as jnp
import mctx

from pizero_ray.agent import mcts, networks
from pizero_ray.config import Config


class PlanResult(NamedTuple):
    abstract_action: jax.Array  # [B] int32: the search's choice
    visit_probs: jax.Array  # [B, k]: the search's action distribution
    root_value: jax.Array  # [B]: the search's value estimate at the root
    root_qvalues: jax.Array | None = None  # [B, k]: each root child's Q (reward + discount x value; 0 unvisited)


Planner = Callable[[networks.Params, jax.Array, jax.Array], PlanResult]


def init(key: jax.Array, config: Config) -> networks.Params:
    """The abstract model's parameters (none without a planner); ``key`` is the agent's key."""
    if config.planner == "none":
        return {}
    latent, h, k = config.latent_size, config.hidden_size, config.num_abstract_actions
    keys = jax.random.split(key, 6)  # the agent's split: 0-2 are the encoder's, memory's and decoder's
    # With chance nodes the dynamics GRU reads the abstract chance outcome;
    # the abstract action first leads to an afterstate.
    dynamics_input = config.chance_outcomes if config.chance_outcomes > 0 else k
    params = {
        "dynamics": networks.gru_init(keys[3], dynamics_input, latent),
        "reward": networks.dense_init(keys[4], latent, 1),
        "prediction": networks.mlp_init(keys[5], (latent, h, 1 + k)),
    }
    if config.chance_outcomes > 0:
        after_keys = jax.random.split(jax.random.fold_in(key, 1), 2)
        params["afterstate"] = networks.gru_init(after_keys[0], k, latent)
        params["afterstate_prediction"] = networks.mlp_init(after_keys[1], (latent, h, 1 + config.chance_outcomes))
    return params


def predict(params: networks.Params, latent: jax.Array) -> tuple[jax.Array, jax.Array]:
    """Prediction function: abstract value [B] and logits over abstract actions [B, k]."""
    out = networks.mlp(params["prediction"], latent)
    return out[..., 0], out[..., 1:]


def dynamics(params: networks.Params, latent: jax.Array, abstract_action: jax.Array, k: int):
    """Dynamics GRU: one-hot abstract action in, abstract reward and next state out."""
    next_latent = networks.gru(params["dynamics"], latent, jax.nn.one_hot(abstract_action, k))
    reward = networks.dense(params["reward"], next_latent)[..., 0]
    return reward, next_latent


def afterstate(params: networks.Params, latent: jax.Array, abstract_action: jax.Array, k: int):
    """With chance nodes: the abstract action leads to an afterstate, its value and chance logits."""
    after = networks.gru(params["afterstate"], latent, jax.nn.one_hot(abstract_action, k))
    out = networks.mlp(params["afterstate_prediction"], after)
    return after, out[..., 0], out[..., 1:]


def make_planner(config: Config) -> Planner:
    """The configured search, its hyperparameters bound: (params, latent [B, L], key) -> PlanResult."""
    k, discount = config.num_abstract_actions, config.abstract_discount
    if config.planner == "none":
        return functools.partial(no_search, num_actions=k)
    if config.chance_outcomes > 0:
        return functools.partial(
            stochastic_muzero_search, num_actions=k, num_outcomes=config.chance_outcomes,
            num_simulations=config.num_simulations, dirichlet_fraction=config.root_noise,
            pb_c_init=config.pb_c_init, pb_c_base=config.pb_c_base, discount=discount,
            loop_fn=mcts.LOOP_FNS[config.simulation_loop])
    if config.planner == "gumbel" and config.num_simulations == k and config.root_noise == 0:
        return functools.partial(every_action_once, num_actions=k, discount=discount)
    # PiZero acts on the most visited abstract action (first index on ties), drawing nothing for it. mctx's
    # search still breaks ties between children with a tiny uniform draw from the key (muzero_action_selection):
    # with no root noise the agent is a deterministic function of (parameters, key).
    policy = mcts.make_policy(config.planner, config.num_simulations, config.root_noise,
                              pb_c_init=config.pb_c_init, pb_c_base=config.pb_c_base, most_visited=True,
                              max_considered_actions=k, simulation_loop=config.simulation_loop)
    return functools.partial(search, policy=policy, recurrent_fn=_recurrent_fn(k, discount))


# mctx's qtransform_completed_by_mix_value defaults: Q-values rescaled to [0, 1] over the root's children, then
# weighed by (maxvisit_init + the most visits of a child) x value_scale.
_MAXVISIT_INIT, _VALUE_SCALE, _RESCALE_EPSILON = 50.0, 0.1, 1e-8


def every_action_once(params: networks.Params, latent: jax.Array, key: jax.Array, *, num_actions: int,
                      discount: float) -> PlanResult:
    """Gumbel MuZero's search with one simulation per abstract action and no Gumbel noise, without the tree.

    With that budget sequential halving's first round visits every root action once, and each simulation
    ends at the child it expands: the search is a one-step lookahead. Here the k children come from one
    batched call of the model instead of k simulations through mctx's tree: on Collect a 30-minute run makes
    about 1.5 times the iterations (docs/planning.md). The result is mctx's up to float rounding (the root
    value is averaged in another order), which tests/agent/test_planner.py checks.
    """
    del key  # no noise is drawn; mctx breaks ties by the first index, as argmax does
    value, logits = predict(params, latent)
    each_action = jnp.broadcast_to(jnp.arange(num_actions)[:, None], (num_actions, latent.shape[0]))
    reward, child = jax.vmap(lambda action: dynamics(params, latent, action, num_actions))(each_action)
    child_value, _ = predict(params, child)
    qvalues = jnp.transpose(reward + discount * child_value)  # [B, k], as mctx's tree.qvalues
    low, high = jnp.min(qvalues, -1, keepdims=True), jnp.max(qvalues, -1, keepdims=True)
    completed = (_MAXVISIT_INIT + 1.0) * _VALUE_SCALE * ((qvalues - low) / jnp.maximum(high - low, _RESCALE_EPSILON))
    score = jnp.maximum(-1e9, logits - jnp.max(logits, -1, keepdims=True) + completed)  # seq_halving's score
    root_value = (value + jnp.sum(qvalues, -1)) / (num_actions + 1.0)  # the root's visits: itself and k children
    return PlanResult(jnp.argmax(score, -1).astype(jnp.int32), jax.nn.softmax(logits + completed), root_value,
                      qvalues)


def no_search(params: networks.Params, latent: jax.Array, key: jax.Array, *, num_actions: int) -> PlanResult:
    """Without a planner: an all-zero result (the decoder then reads the abstract state only)."""
    del params, key
    batch = latent.shape[0]
    return PlanResult(jnp.zeros((batch,), jnp.int32), jnp.zeros((batch, num_actions)), jnp.zeros((batch,)),
                      jnp.zeros((batch, num_actions)))


def _root(params: networks.Params, latent: jax.Array) -> mctx.RootFnOutput:
    value, logits = predict(params, latent)
    return mctx.RootFnOutput(prior_logits=logits, value=value, embedding=latent)


def _recurrent_fn(num_actions: int, discount: float):
    def recurrent_fn(params, rng, action, embedding):
        del rng
        reward, next_latent = dynamics(params, embedding, action, num_actions)
        next_value, next_logits = predict(params, next_latent)
        output = mctx.RecurrentFnOutput(reward=reward, discount=jnp.full_like(reward, discount),
                                        prior_logits=next_logits, value=next_value)
        return output, next_latent

    return recurrent_fn


def search(params, latent, key, *, policy: mcts.SearchPolicy, recurrent_fn) -> PlanResult:
    """MCTS over the abstract model with ``policy`` (mctx's MuZero or Gumbel MuZero, bound by ``mcts``)."""
    output = policy(params, key, _root(params, latent), recurrent_fn)
    summary = output.search_tree.summary()
    return PlanResult(output.action.astype(jnp.int32), output.action_weights, summary.value, summary.qvalues)


def stochastic_muzero_search(params, latent, key, *, num_actions: int, num_outcomes: int, num_simulations: int,
                             dirichlet_fraction: float, pb_c_init: float, pb_c_base: float,
                             discount: float, loop_fn=jax.lax.fori_loop) -> PlanResult:
    """Stochastic MuZero search: abstract action -> afterstate -> abstract chance outcome -> state.

    The chance outcomes are as invented as everything else in the model: ES
    decides what, if anything, they stand for (in 2048, where the tile appears).
    """

    def decision_fn(params, rng, action, embedding):
        del rng
        after, after_value, chance_logits = afterstate(params, embedding, action, num_actions)
        return mctx.DecisionRecurrentFnOutput(chance_logits=chance_logits, afterstate_value=after_value), after

    def chance_fn(params, rng, outcome, after):
        del rng
        reward, next_latent = dynamics(params, after, outcome, num_outcomes)
        next_value, next_logits = predict(params, next_latent)
        output = mctx.ChanceRecurrentFnOutput(
            action_logits=next_logits, value=next_value, reward=reward, discount=jnp.full_like(reward, discount),
        )
        return output, next_latent

    output = mctx.stochastic_muzero_policy(
        params, key, _root(params, latent), decision_fn, chance_fn, num_simulations,
        dirichlet_fraction=dirichlet_fraction, pb_c_init=pb_c_init, pb_c_base=pb_c_base, loop_fn=loop_fn,
    )
    abstract_action = jnp.argmax(output.action_weights, axis=-1)
    summary = output.search_tree.summary()
    return PlanResult(abstract_action.astype(jnp.int32), output.action_weights, summary.value, summary.qvalues)
