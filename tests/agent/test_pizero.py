import jax
import numpy as np
import pytest

from pizero_ray.agent import make_agent, without_memory
from pizero_ray.config import build_config


def _observations(env, batch, seed=0):
    return jax.vmap(env.reset)(jax.random.split(jax.random.PRNGKey(seed), batch))


@pytest.fixture(scope="module")
def tiny_agent(tiny_config, tsp_env):
    return make_agent(tiny_config, tsp_env.spec)


@pytest.fixture(scope="module")
def act(tiny_agent):
    """The tiny agent's act, jitted once for the module: its tests share a batch of 5, so one compile serves them."""
    return jax.jit(tiny_agent.act)


def test_act_shapes_and_legal_actions(tiny_config, tsp_env, tiny_agent, act):
    params = tiny_agent.init(jax.random.PRNGKey(0))
    _, obs = _observations(tsp_env, 5)
    obs = obs._replace(action_mask=obs.action_mask.at[:, :9].set(False))  # only city 9 is legal
    memory = tiny_agent.initial_memory(5)
    action, new_memory, info = act(params, memory, obs, jax.random.PRNGKey(1))
    assert action.shape == (5,) and list(np.asarray(action)) == [9] * 5
    assert new_memory.shape == (5, tiny_config.memory_size)
    assert not np.allclose(new_memory, memory)  # memory takes in observation and action
    assert info.latent.shape == (5, tiny_config.latent_size)
    assert info.plan.visit_probs.shape == (5, tiny_config.num_abstract_actions)


def _act_with_keys(config, env, seeds, batch=16):
    """What the agent does on the same observations, memory and parameters with each key in turn."""
    agent = make_agent(config, env.spec)
    params = agent.init(jax.random.PRNGKey(0))
    _, obs = _observations(env, batch)
    act = jax.jit(agent.act)
    return [jax.tree_util.tree_map(np.asarray, act(params, agent.initial_memory(batch), obs, jax.random.PRNGKey(s)))
            for s in seeds]


def _same(first, second) -> bool:
    leaves = zip(jax.tree_util.tree_leaves(first), jax.tree_util.tree_leaves(second))
    return all(np.array_equal(a, b) for a, b in leaves)


def test_the_key_does_not_move_an_agent_that_neither_searches_nor_samples(tsp_env):
    first, second = _act_with_keys(build_config("tiny", planner="none"), tsp_env, [1, 2])
    assert _same(first, second)


def test_root_noise_is_drawn_from_the_key(tsp_env):
    """With Dirichlet noise at the root the search's visits follow the key (and only the key)."""
    first, again, other = _act_with_keys(build_config("tiny", root_noise=0.5), tsp_env, [1, 1, 2])
    assert _same(first, again)
    assert not np.array_equal(first[2].plan.visit_probs, other[2].plan.visit_probs)


def test_sampled_actions_are_drawn_from_the_key(tsp_env):
    config = build_config("tiny", planner="none", action_selection="sample", action_noise=1.0)
    first, again, other = _act_with_keys(config, tsp_env, [1, 1, 2])
    assert _same(first, again)
    assert not np.array_equal(first[0], other[0])  # some of the 16 episodes take another city


def test_no_planner_has_no_abstract_model_and_acts(tsp_env):
    agent = make_agent(build_config("tiny", planner="none"), tsp_env.spec)
    params = agent.init(jax.random.PRNGKey(0))
    assert set(params) == {"encoder", "memory", "decoder"}
    _, obs = _observations(tsp_env, 3)
    action, _, info = agent.act(params, agent.initial_memory(3), obs, jax.random.PRNGKey(0))
    assert action.shape == (3,)
    assert not np.asarray(info.plan.visit_probs).any()  # no search, an all-zero result


def test_the_memory_reads_the_action_taken(tiny_config, tsp_env, tiny_agent, act):
    # The same observations and memory, but different legal actions forced by the
    # mask: the new memories differ, because the GRU reads the taken action's features.
    params = tiny_agent.init(jax.random.PRNGKey(0))
    _, obs = _observations(tsp_env, 5)
    memory = tiny_agent.initial_memory(5)
    memories = []
    for city in (3, 7):
        only = obs._replace(action_mask=np.broadcast_to(np.arange(obs.action_mask.shape[1]) == city,
                                                        obs.action_mask.shape))
        action, new_memory, _ = act(params, memory, only, jax.random.PRNGKey(0))
        assert list(np.asarray(action)) == [city] * 5
        memories.append(np.asarray(new_memory))
    for first, second in zip(*memories):  # each observation's memory
        assert not np.allclose(first, second)


def test_planner_choice_leaves_the_encoder_memory_and_decoder_initialisation_alone(tsp_env):
    # A planner-vs-none comparison starts from the same encoder, memory and decoder.
    with_planner = make_agent(build_config("tiny"), tsp_env.spec).init(jax.random.PRNGKey(5))
    without = make_agent(build_config("tiny", planner="none"), tsp_env.spec).init(jax.random.PRNGKey(5))
    for name in ("encoder", "memory"):
        for a, b in zip(jax.tree_util.tree_leaves(with_planner[name]), jax.tree_util.tree_leaves(without[name])):
            np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    # The decoder's context is smaller without a planner, its per-action part is the same.
    np.testing.assert_array_equal(np.asarray(with_planner["decoder"]["features"]["w"]),
                                  np.asarray(without["decoder"]["features"]["w"]))


def test_without_memory_acts_as_the_agent_on_zero_memory_and_keeps_it_zero(tsp_env, tiny_agent, act):
    params = tiny_agent.init(jax.random.PRNGKey(0))
    _, obs = _observations(tsp_env, 5)
    zeros = tiny_agent.initial_memory(5)
    action, memory, _ = jax.jit(without_memory(tiny_agent).act)(params, zeros, obs, jax.random.PRNGKey(2))
    expected, remembered, _ = act(params, zeros, obs, jax.random.PRNGKey(2))
    np.testing.assert_array_equal(np.asarray(action), np.asarray(expected))
    assert not np.asarray(memory).any() and np.asarray(remembered).any()  # the agent itself would remember
