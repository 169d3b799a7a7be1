import jax
import jax.numpy as jnp
import mctx
import numpy as np
import pytest

from pizero_ray.agent import make_agent, mcts, planner
from pizero_ray.config import ConfigError, build_config


def _setup(tsp_env, batch=4, **overrides):
    config = build_config("tiny", **overrides)
    params = make_agent(config, tsp_env.spec).init(jax.random.PRNGKey(0))
    latent = jax.random.normal(jax.random.PRNGKey(1), (batch, config.latent_size))
    return config, params, latent


@pytest.mark.parametrize("planner_name", ["muzero", "gumbel"])
def test_the_planner_searches_the_learned_model(tsp_env, planner_name):
    config, params, latent = _setup(tsp_env, planner=planner_name, num_simulations=6, num_abstract_actions=3)
    plan = jax.jit(lambda p, z: planner.make_planner(config)(p, z, jax.random.PRNGKey(2)))
    result = plan(params, latent)
    if planner_name == "muzero":
        # visit probabilities are visit counts over the simulation budget
        counts = np.asarray(result.visit_probs) * config.num_simulations
        np.testing.assert_allclose(counts, np.round(counts), atol=1e-4)
    np.testing.assert_allclose(np.asarray(result.visit_probs).sum(-1), 1.0, atol=1e-5)
    # The search reads the learned dynamics: changing its reward head changes the root value.
    changed = dict(params, reward={"w": params["reward"]["w"] + 3.0, "b": params["reward"]["b"] + 1.0})
    assert not np.allclose(plan(changed, latent).root_value, result.root_value)


def test_muzero_acts_on_the_most_visited_abstract_action(tsp_env):
    config, params, latent = _setup(tsp_env, batch=16, num_simulations=8, num_abstract_actions=3, root_noise=0.25)
    result = jax.jit(lambda p, z: planner.make_planner(config)(p, z, jax.random.PRNGKey(2)))(params, latent)
    np.testing.assert_array_equal(np.asarray(result.abstract_action), np.argmax(result.visit_probs, axis=-1))


def test_chance_nodes_search_an_afterstate_model(tsp_env):
    config, params, latent = _setup(tsp_env, chance_outcomes=3, num_simulations=8, num_abstract_actions=3)
    assert params["dynamics"]["input"]["w"].shape[0] == 3  # the dynamics GRU reads a chance outcome
    plan = jax.jit(lambda p: planner.make_planner(config)(p, latent, jax.random.PRNGKey(2)))
    result = plan(params)
    assert result.visit_probs.shape == (4, 3)
    np.testing.assert_allclose(np.asarray(result.visit_probs).sum(-1), 1.0, atol=1e-5)
    # The search reads the afterstate model: changing its chance head changes the root value.
    head = params["afterstate_prediction"]["layer1"]
    changed = dict(params, afterstate_prediction={**params["afterstate_prediction"],
                                                  "layer1": {"w": head["w"] * 5.0, "b": head["b"] + 2.0}})
    assert not np.allclose(plan(changed).root_value, result.root_value)


def test_chance_nodes_need_the_muzero_planner():
    with pytest.raises(ConfigError, match="chance nodes need the muzero planner"):
        build_config("tiny", chance_outcomes=3, planner="gumbel")


def test_no_planner_has_no_abstract_model():
    config = build_config("tiny", planner="none")
    assert planner.init(jax.random.PRNGKey(0), config) == {}
    result = planner.make_planner(config)({}, jnp.ones((2, config.latent_size)), jax.random.PRNGKey(0))
    assert result.visit_probs.shape == (2, config.num_abstract_actions) and not np.asarray(result.visit_probs).any()


def test_the_noise_free_most_visited_search_is_mctx_muzero_policy_exactly(tsp_env):
    # The planner skips muzero_policy's Dirichlet sampling when its weight is 0
    # (a speed-up); the tree must be the one muzero_policy builds.
    config, params, latent = _setup(tsp_env, batch=16, num_simulations=8, num_abstract_actions=3)
    key = jax.random.PRNGKey(4)
    ours = jax.jit(lambda p, z: planner.make_planner(config)(p, z, key))(params, latent)

    def recurrent_fn(p, rng, action, embedding):
        reward, next_latent = planner.dynamics(p, embedding, action, config.num_abstract_actions)
        value, logits = planner.predict(p, next_latent)
        discount = jnp.full_like(reward, config.abstract_discount)
        return mctx.RecurrentFnOutput(reward=reward, discount=discount, prior_logits=logits, value=value), next_latent

    def reference(p, z):
        value, logits = planner.predict(p, z)
        root = mctx.RootFnOutput(prior_logits=logits, value=value, embedding=z)
        return mctx.muzero_policy(p, key, root, recurrent_fn, config.num_simulations, dirichlet_fraction=0.0,
                                  pb_c_init=config.pb_c_init, pb_c_base=config.pb_c_base)

    theirs = jax.jit(reference)(params, latent)
    np.testing.assert_array_equal(np.asarray(ours.visit_probs), np.asarray(theirs.action_weights))
    np.testing.assert_array_equal(np.asarray(ours.root_value), np.asarray(theirs.search_tree.summary().value))
    assert len({tuple(row) for row in np.asarray(ours.visit_probs).round(3)}) > 1  # the searches differ per state


def test_the_root_qvalues_are_each_root_childs_reward_and_discounted_value():
    """What the decoder reads as "qvalues": mctx's summary of the root's children, zero where unvisited."""
    import jax

    from pizero_ray.agent import planner
    from pizero_ray.config import build_config

    config = build_config("tiny", num_simulations=3, num_abstract_actions=2)
    params = planner.init(jax.random.PRNGKey(0), config)
    latent = jax.random.normal(jax.random.PRNGKey(1), (4, config.latent_size))
    plan = planner.make_planner(config)(params, latent, jax.random.PRNGKey(2))
    assert plan.root_qvalues.shape == (4, 2)
    visited = np.asarray(plan.visit_probs) > 0
    assert np.all(np.asarray(plan.root_qvalues)[~visited] == 0.0)
    assert np.any(np.asarray(plan.root_qvalues)[visited] != 0.0)


@pytest.mark.parametrize("num_abstract_actions", [2, 3, 4])
def test_gumbel_with_one_simulation_per_abstract_action_is_mctx_search_without_the_tree(tsp_env, num_abstract_actions):
    k = num_abstract_actions
    config, params, latent = _setup(tsp_env, batch=64, planner="gumbel", num_simulations=k, num_abstract_actions=k,
                                    chance_outcomes=0)
    key = jax.random.PRNGKey(4)
    assert planner.make_planner(config).func is planner.every_action_once
    ours = jax.jit(lambda p, z: planner.make_planner(config)(p, z, key))(params, latent)
    policy = mcts.make_policy("gumbel", k, 0.0, max_considered_actions=k)
    theirs = jax.jit(lambda p, z: planner.search(p, z, key, policy=policy,
                                                 recurrent_fn=planner._recurrent_fn(k, config.abstract_discount)))(
        params, latent)
    np.testing.assert_array_equal(np.asarray(ours.abstract_action), np.asarray(theirs.abstract_action))
    for name in ("visit_probs", "root_value", "root_qvalues"):
        np.testing.assert_allclose(np.asarray(getattr(ours, name)), np.asarray(getattr(theirs, name)), rtol=1e-5,
                                   atol=1e-6, err_msg=name)
    assert len(set(np.asarray(ours.abstract_action).tolist())) > 1  # the choice depends on the state


def test_gumbel_keeps_the_tree_with_noise_or_another_budget():
    for overrides in ({"num_simulations": 5}, {"root_noise": 1.0}):
        config = build_config("tiny", planner="gumbel", num_abstract_actions=4, chance_outcomes=0,
                              **{"num_simulations": 4, **overrides})
        assert planner.make_planner(config).func is planner.search
