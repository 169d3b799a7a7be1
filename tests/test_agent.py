import jax
import jax.numpy as jnp
import numpy as np
import pytest

from envs.base import EnvSpec, Observation
from pizero_ray.agent import pizero as agent
from pizero_ray.agent import planner
from pizero_ray.config import build_config


def _observations(env, batch, seed=0):
    states, obs = jax.vmap(env.reset)(jax.random.split(jax.random.PRNGKey(seed), batch))
    return states, obs


@pytest.fixture(scope="module")
def tiny_act(tiny_config, tsp_env):
    return jax.jit(lambda p, m, o, k: agent.act(p, tiny_config, tsp_env.spec, m, o, k))


def test_act_shapes_and_legal_actions(tiny_config, tsp_env, tiny_act):
    params = agent.init_params(jax.random.PRNGKey(0), tiny_config, tsp_env.spec)
    _, obs = _observations(tsp_env, 5)
    obs = obs._replace(action_mask=obs.action_mask.at[:, :9].set(False))  # only city 9 is legal
    memory = agent.initial_memory(tiny_config, 5)
    action, new_memory, info = tiny_act(params, memory, obs, jax.random.PRNGKey(1))
    assert action.shape == (5,) and list(np.asarray(action)) == [9] * 5
    assert new_memory.shape == (5, tiny_config.memory_size)
    assert not np.allclose(new_memory, memory)  # memory takes in observation and action
    assert info.latent.shape == (5, tiny_config.latent_size)
    assert info.plan.visit_probs.shape == (5, tiny_config.num_abstract_actions)


def test_act_is_deterministic_given_a_key(tiny_config, tsp_env, tiny_act):
    params = agent.init_params(jax.random.PRNGKey(0), tiny_config, tsp_env.spec)
    _, obs = _observations(tsp_env, 4)
    memory = agent.initial_memory(tiny_config, 4)
    first = tiny_act(params, memory, obs, jax.random.PRNGKey(3))
    second = tiny_act(params, memory, obs, jax.random.PRNGKey(3))
    for a, b in zip(jax.tree_util.tree_leaves(first), jax.tree_util.tree_leaves(second)):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))


@pytest.mark.parametrize("planner_name", ["muzero", "gumbel"])
def test_planner_searches_the_learned_model(tsp_env, planner_name):
    config = build_config("tiny", planner=planner_name, num_simulations=6, num_abstract_actions=3)
    params = agent.init_params(jax.random.PRNGKey(0), config, tsp_env.spec)
    latent = jax.random.normal(jax.random.PRNGKey(1), (4, config.latent_size))
    plan = jax.jit(lambda p, z: planner.plan(p, config, z, jax.random.PRNGKey(2)))
    result = plan(params, latent)
    if planner_name == "muzero":
        # visit probabilities are visit counts over the simulation budget
        counts = np.asarray(result.visit_probs) * config.num_simulations
        np.testing.assert_allclose(counts, np.round(counts), atol=1e-4)
    np.testing.assert_allclose(np.asarray(result.visit_probs).sum(-1), 1.0, atol=1e-5)
    # The search reads the learned dynamics: changing its reward head changes the root value.
    changed = dict(params, reward={"w": params["reward"]["w"] + 3.0, "b": params["reward"]["b"] + 1.0})
    assert not np.allclose(plan(changed, latent).root_value, result.root_value)


def test_no_planner_has_no_abstract_model(tsp_env):
    config = build_config("tiny", planner="none")
    params = agent.init_params(jax.random.PRNGKey(0), config, tsp_env.spec)
    assert "dynamics" not in params and "prediction" not in params
    _, obs = _observations(tsp_env, 3)
    action, _, _ = agent.act(params, config, tsp_env.spec, agent.initial_memory(config, 3), obs, jax.random.PRNGKey(0))
    assert action.shape == (3,)


def test_sampled_actions_respect_the_mask(tsp_env):
    config = build_config("tiny", action_selection="sample", action_noise=5.0)
    params = agent.init_params(jax.random.PRNGKey(0), config, tsp_env.spec)
    _, obs = _observations(tsp_env, 64)
    obs = obs._replace(action_mask=obs.action_mask.at[:, ::2].set(False))
    action, _, _ = jax.jit(lambda o: agent.act(params, config, tsp_env.spec, agent.initial_memory(config, 64), o,
                                               jax.random.PRNGKey(0)))(obs)
    assert np.all(np.asarray(action) % 2 == 1)
    assert len(set(np.asarray(action).tolist())) > 1  # sampling, not argmax


def test_continuous_actions_stay_in_bounds():
    spec = EnvSpec(observation_size=6, horizon=3, num_actions=0, action_feature_size=0, action_dim=2,
                   action_low=-1.0, action_high=2.0)
    config = build_config("tiny", action_selection="sample", action_noise=3.0)
    params = agent.init_params(jax.random.PRNGKey(0), config, spec)
    vector = jax.random.normal(jax.random.PRNGKey(1), (16, 6))
    obs = Observation(vector, jnp.zeros((16, 0, 0)), jnp.zeros((16, 0), bool))
    action, _, _ = agent.act(params, config, spec, agent.initial_memory(config, 16), obs, jax.random.PRNGKey(2))
    assert action.shape == (16, 2)
    assert np.all((np.asarray(action) >= -1.0) & (np.asarray(action) <= 2.0))


def test_chance_nodes_search_an_afterstate_model(tsp_env):
    config = build_config("tiny", chance_outcomes=3, num_simulations=8, num_abstract_actions=3)
    params = agent.init_params(jax.random.PRNGKey(0), config, tsp_env.spec)
    assert params["dynamics"]["input"]["w"].shape[0] == 3  # the dynamics GRU reads a chance outcome
    latent = jax.random.normal(jax.random.PRNGKey(1), (4, config.latent_size))
    plan = jax.jit(lambda p: planner.plan(p, config, latent, jax.random.PRNGKey(2)))
    result = plan(params)
    assert result.visit_probs.shape == (4, 3)
    np.testing.assert_allclose(np.asarray(result.visit_probs).sum(-1), 1.0, atol=1e-5)
    # The search reads the afterstate model: changing its chance head changes the root value.
    head = params["afterstate_prediction"]["layer1"]
    changed = dict(params, afterstate_prediction={**params["afterstate_prediction"],
                                                  "layer1": {"w": head["w"] * 5.0, "b": head["b"] + 2.0}})
    assert not np.allclose(plan(changed).root_value, result.root_value)


def test_chance_nodes_need_the_muzero_planner():
    from pizero_ray.config import ConfigError

    with pytest.raises(ConfigError, match="chance nodes need the muzero planner"):
        build_config("tiny", chance_outcomes=3, planner="gumbel")


def test_muzero_search_without_root_noise_is_mctx_muzero_policy_exactly(tsp_env):
    # planner.plan skips muzero_policy's Dirichlet sampling when its weight is 0
    # (a speed-up); the tree must be the one muzero_policy builds.
    import mctx

    config = build_config("tiny", num_simulations=8, num_abstract_actions=3)
    params = agent.init_params(jax.random.PRNGKey(0), config, tsp_env.spec)
    latent = jax.random.normal(jax.random.PRNGKey(1), (16, config.latent_size))
    key = jax.random.PRNGKey(4)
    ours = jax.jit(lambda p, z: planner.plan(p, config, z, key))(params, latent)

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
