import jax
import jax.numpy as jnp
import numpy as np
import pytest

from pizero_ray import es
from pizero_ray.agent import episodes, make_agent
from pizero_ray.config import build_config
from pizero_ray.es import population


def pair_scorer(config, env):
    """(theta, scores(seed, first_pair) of the chunk from first_pair on), as a worker computes them."""
    theta, layout = population.flat_params(config, env)
    evaluate = population.make_pair_scorer(config, env, layout)
    noise = es.gradient_parts(config, layout.perturbation).noise  # the function that regenerates the noise

    def scores(seed, first_pair=0):
        pairs = np.arange(first_pair, first_pair + config.chunk_size, dtype=np.int32)
        return np.asarray(evaluate(theta, np.uint32(seed), pairs, noise(np.uint32(seed), np.int32(first_pair))))

    return theta, scores


@pytest.fixture(scope="module")
def evaluator(tiny_config, tsp_env):
    return pair_scorer(tiny_config, tsp_env)


def test_pair_scores_are_a_function_of_seed_and_indices(evaluator, tiny_config):
    _, scores = evaluator
    first = scores(11)
    again = scores(11)
    assert first.shape == (tiny_config.chunk_size, 2)
    np.testing.assert_array_equal(first, again)
    other = scores(12)
    assert not np.array_equal(first, other)
    assert np.all(first < 0) and np.all(first > -10)  # minus a tour length in the unit square


def test_both_halves_of_a_pair_play_the_same_episodes(tsp_env):
    # With a vanishing sigma both members act identically, so equal scores
    # show they played the same instances; different pairs play different ones.
    config = build_config("tiny", sigma=1e-9, chunk_size=2)
    scores = pair_scorer(config, tsp_env)[1](5)
    np.testing.assert_array_equal(scores[:, 0], scores[:, 1])
    assert scores[0, 0] != scores[1, 0]


def test_with_common_episodes_every_pair_plays_the_same_episodes_new_each_iteration(tsp_env):
    # A vanishing sigma: every member acts as theta does, so equal scores show equal instances.
    config = build_config("tiny", sigma=1e-9, population=4, chunk_size=4, common_episodes=True)
    scores = pair_scorer(config, tsp_env)[1]
    first = scores(5)
    np.testing.assert_array_equal(first, np.full_like(first, first[0, 0]))
    assert scores(6)[0, 0] != first[0, 0]  # another iteration, other episodes
    own = pair_scorer(build_config("tiny", sigma=1e-9, population=4, chunk_size=4), tsp_env)[1](5)
    assert own[0, 0] == first[0, 0] and len(set(own[:, 0])) > 1  # pair 0's episodes, which the others share


def test_flat_parameters_round_trip(tiny_config, tsp_env):
    theta, layout = population.flat_params(tiny_config, tsp_env)
    assert theta.dtype == jnp.float32 and theta.shape == (layout.size,)
    params = layout.unravel(theta)
    assert set(params) == {"encoder", "memory", "decoder", "dynamics", "reward", "prediction"}
    initial = make_agent(tiny_config, tsp_env.spec).init(jax.random.PRNGKey(tiny_config.seed))
    # Both layouts, the driver's and the one from shapes alone (a worker's), unravel theta into the very initial
    # pytree.
    for flat_layout in (layout, population.params_layout(tiny_config, tsp_env)):
        params = flat_layout.unravel(theta)
        assert flat_layout.size == layout.size and jax.tree.structure(params) == jax.tree.structure(initial)
        for leaf, expected in zip(jax.tree.leaves(params), jax.tree.leaves(initial)):
            assert leaf.dtype == expected.dtype and np.array_equal(leaf, expected)
        assert flat_layout.perturbation.leaf_shapes == tuple(leaf.shape for leaf in jax.tree.leaves(initial))


@pytest.mark.parametrize("env_name, extra", [
    ("tsp", {}),
    ("flp", {"chance_outcomes": 2}),  # continuous decoder; afterstate and chance networks
])
def test_low_rank_members_play_exactly_theta_plus_the_expanded_noise(tsp_env, env_name, extra):
    # The evaluator never forms a low-rank member's matrices; scoring the
    # formed matrices directly must give the same scores.
    from pizero_ray import envs, es

    config = build_config("tiny", env=env_name, perturbation_rank=2, sigma=0.5, population=3, chunk_size=3, **extra)
    env = tsp_env if env_name == "tsp" else envs.make(env_name)
    theta, layout = population.flat_params(config, env)
    scores = pair_scorer(config, env)[1](9)
    key = es.iteration_key(np.uint32(9))
    agent = make_agent(config, env.spec)
    member_score = jax.jit(lambda member, episode_key: jnp.mean(
        episodes.run_episodes(agent, layout.unravel(member), env, episode_key, config.episodes_per_member)))
    expected = []
    for i in range(3):
        z = es.expand_noise(es.pair_noise(key, i, layout.perturbation.noise_size), layout.perturbation)
        episode_key = es.pair_episode_key(key, i)
        expected.append([float(member_score(theta + s * z, episode_key)) for s in (config.sigma, -config.sigma)])
    np.testing.assert_allclose(scores, expected, rtol=1e-5)
    assert not np.array_equal(scores[:, 0], scores[:, 1])
    assert layout.perturbation.noise_size < layout.size / 2


@pytest.mark.parametrize("env_name, extra", [
    ("tsp", {}),
    ("examples.corridor:make", {}),  # episodes that end before the horizon
    ("2048", {"chance_outcomes": 2, "env_args": {"horizon": 30}}),  # chance nodes
    ("tsp", {"planner": "gumbel", "num_simulations": 3}),  # more simulations than abstract actions: mctx's tree
])
def test_the_loops_compiled_do_not_change_the_scores(env_name, extra):
    """How the episode loop and the simulations are compiled (config.episode_loop, config.simulation_loop)
    changes the program's while loops, not one bit of any score."""
    import dataclasses

    from pizero_ray import envs

    config = build_config("tiny", env=env_name, population=4, chunk_size=4, **extra)
    env = envs.make(env_name, **config.env_kwargs())
    baseline = pair_scorer(config, env)[1](3)  # until_done, fori: the defaults
    # Each setting changed alone: they compile different loops (the episode's, the search's), so the pair adds
    # no loop of its own, and each program compiled costs seconds.
    for change in ({"episode_loop": "horizon"}, {"simulation_loop": "unrolled"}):
        variant = dataclasses.replace(config, **change)
        np.testing.assert_array_equal(pair_scorer(variant, env)[1](3), baseline, err_msg=str(change))
