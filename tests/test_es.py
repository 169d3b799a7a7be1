import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

from pizero_ray import es
from pizero_ray.config import build_config


def test_member_noise_is_the_same_alone_or_in_a_chunk():
    key = es.iteration_key(1234)
    alone = es.pair_noise(key, jnp.int32(5), 300)
    chunk = jax.jit(jax.vmap(es.pair_noise, in_axes=(None, 0, None)), static_argnums=2)(key, jnp.arange(3, 8), 300)
    np.testing.assert_array_equal(np.asarray(alone), np.asarray(chunk[2]))
    assert not np.allclose(chunk[0], chunk[1])
    other_iteration = es.pair_noise(es.iteration_key(1235), jnp.int32(5), 300)
    assert not np.allclose(alone, other_iteration)


def test_episode_key_differs_from_noise_stream_and_between_pairs():
    key = es.iteration_key(7)
    a, b = es.pair_episode_key(key, 0), es.pair_episode_key(key, 1)
    assert not np.array_equal(np.asarray(a), np.asarray(b))


def test_iteration_seed_is_a_pure_function():
    assert es.iteration_seed(0, 3) == es.iteration_seed(0, 3)
    seeds = {es.iteration_seed(s, i) for s in range(3) for i in range(50)}
    assert len(seeds) == 150
    assert all(0 <= s < 2**32 for s in seeds)


def test_centered_ranks():
    x = jnp.array([[3.0, -1.0], [10.0, 0.5]])
    ranks = es.centered_ranks(x)
    np.testing.assert_allclose(ranks, [[0.5 / 3 * 2 - 0.5 + 1 / 3, -0.5], [0.5, -0.5 + 1 / 3]], atol=1e-6)
    assert float(ranks.sum()) == pytest.approx(0.0, abs=1e-6)


def _position_ranks(x):
    """The old shaping (ties broken by position): the reference for untied scores."""
    flat = np.asarray(x, np.float64).reshape(-1)
    ranks = np.empty(flat.size)
    ranks[np.argsort(flat, kind="stable")] = np.arange(flat.size)
    return (ranks / (flat.size - 1) - 0.5).reshape(np.shape(x))


def test_untied_scores_rank_as_before():
    scores = np.random.default_rng(3).standard_normal((50, 2)).astype(np.float32)
    np.testing.assert_allclose(es.centered_ranks(jnp.asarray(scores)), _position_ranks(scores), atol=1e-6)


def test_a_tied_pair_gets_weight_zero_and_ties_share_their_average_rank():
    scores = jnp.array([[2.0, 2.0], [0.0, 1.0], [1.0, 3.0]])  # pair 0 ties; 1.0 appears twice
    weights = es.pair_weights(scores, "centered_ranks")
    assert float(weights[0]) == 0.0
    ranks = es.centered_ranks(scores)
    assert float(ranks[1, 1]) == float(ranks[2, 0]) == pytest.approx(1.5 / 5 - 0.5)
    assert float(ranks.sum()) == pytest.approx(0.0, abs=1e-6)


def test_a_population_that_ties_throughout_gives_no_update_direction():
    scores = jnp.zeros((8, 2))  # every member covers 0 goals, as early in Sokoban
    weights = es.pair_weights(scores, "centered_ranks")
    np.testing.assert_array_equal(weights, np.zeros(8))
    valid = jnp.array([True] * 6 + [False] * 2)
    np.testing.assert_array_equal(es.pair_weights(scores, "centered_ranks", valid), np.zeros(8))
    perturbation = es.Perturbation(((30,),), 0)
    direction = es.pseudo_gradient(es.iteration_key(5), weights, 0.1, perturbation, chunk_size=4)
    np.testing.assert_array_equal(direction, np.zeros(30))


def test_chunked_gradient_equals_the_direct_sum():
    key = es.iteration_key(99)
    n, size, sigma = 12, 50, 0.1
    weights = jnp.linspace(-1, 1, n)
    direct = sum(float(weights[i]) * np.asarray(es.pair_noise(key, i, size)) for i in range(n)) / (2 * sigma * n)
    chunked = es.pseudo_gradient(key, weights, sigma, es.Perturbation(((size,),), 0), chunk_size=4)
    np.testing.assert_allclose(np.asarray(chunked), direct, rtol=1e-5, atol=1e-6)


def _quadratic_scores(theta, key, n, sigma, target, perturbation=None):
    perturbation = perturbation or es.Perturbation(((theta.shape[0],),), 0)
    noise = np.stack([np.asarray(es.expand_noise(es.pair_noise(key, i, perturbation.noise_size), perturbation))
                      for i in range(n)])
    score = lambda x: -np.sum((x - target) ** 2, axis=-1)
    return np.stack([score(theta + sigma * noise), score(theta - sigma * noise)], axis=1)


def test_antithetic_gradient_of_a_quadratic_points_uphill():
    size, n, sigma = 20, 200, 0.05
    theta = np.zeros(size, np.float32)
    target = np.linspace(-1, 1, size).astype(np.float32)
    key = es.iteration_key(3)
    scores = _quadratic_scores(theta, key, n, sigma, target)
    weights = es.pair_weights(jnp.asarray(scores), "none")
    g = np.asarray(es.pseudo_gradient(key, weights, sigma, es.Perturbation(((size,),), 0), 20))
    true_gradient = 2 * (target - theta)
    cosine = g @ true_gradient / (np.linalg.norm(g) * np.linalg.norm(true_gradient))
    assert cosine > 0.7


@pytest.mark.parametrize("shaping, rank", [("none", 0), ("centered_ranks", 0), ("centered_ranks", 2)])
def test_adam_ascent_steps_climb_the_quadratic(shaping, rank):
    shapes = ((4, 6), (6,)) if rank else ((10,),)
    perturbation = es.Perturbation(shapes, rank)
    size = perturbation.parameter_size
    config = build_config("tiny", population=64, chunk_size=16, sigma=0.05, learning_rate=0.05, fitness_shaping=shaping,
                          perturbation_rank=rank)
    update = es.make_update(config, perturbation)
    theta = jnp.zeros(size)
    state = update.optimizer.init(theta)
    target = np.linspace(-1, 1, size).astype(np.float32)
    start = np.sum(target**2)
    for iteration in range(30):
        seed = es.iteration_seed(0, iteration)
        scores = _quadratic_scores(np.asarray(theta), es.iteration_key(seed), 64, 0.05, target, perturbation)
        theta, state, _ = update(theta, state, np.uint32(seed), jnp.asarray(scores, jnp.float32), jnp.ones(64, bool))
    assert np.sum((np.asarray(theta) - target) ** 2) < 0.5 * start
    assert isinstance(state[1][0], optax.ScaleByAdamState) and int(state[1][0].count) == 30


def test_low_rank_noise_sizes_and_structure():
    perturbation = es.Perturbation(((12, 9), (9,), (9, 1)), 2)
    assert perturbation.parameter_size == 12 * 9 + 9 + 9
    assert perturbation.noise_size == (12 + 9) * 2 + 9 + (9 + 1) * 2
    key = es.iteration_key(5)
    directions = np.stack([np.asarray(es.expand_noise(es.pair_noise(key, i, perturbation.noise_size), perturbation))
                           for i in range(400)])
    assert directions.shape == (400, perturbation.parameter_size)
    # each matrix's noise has rank r; its entries (and the biases') keep unit variance, as full-rank noise
    assert np.linalg.matrix_rank(directions[0, :108].reshape(12, 9)) == 2
    assert 0.85 < directions.var() < 1.15
    assert abs(directions.mean()) < 0.05
    np.testing.assert_array_equal(es.expand_noise(jnp.arange(5.0), es.Perturbation(((5,),), 0)), jnp.arange(5.0))


def test_low_rank_gradient_equals_the_direct_sum_of_expanded_noise():
    perturbation = es.Perturbation(((7, 5), (5,), (5, 3)), 3)
    key = es.iteration_key(11)
    n, sigma = 12, 0.1
    weights = jnp.linspace(-1, 1, n)
    noise = [es.pair_noise(key, i, perturbation.noise_size) for i in range(n)]
    direct = sum(float(weights[i]) * np.asarray(es.expand_noise(noise[i], perturbation)) for i in range(n))
    np.testing.assert_allclose(es.weighted_noise_sum(weights, jnp.stack(noise), perturbation), direct,
                               rtol=1e-5, atol=1e-5)
    chunked = es.pseudo_gradient(key, weights, sigma, perturbation, chunk_size=4)
    np.testing.assert_allclose(np.asarray(chunked), direct / (2 * sigma * n), rtol=1e-5, atol=1e-5)


def test_dropped_pairs_take_no_rank_and_no_weight():
    scores = jnp.array([[1.0, 2.0], [100.0, -100.0], [3.0, 0.0]])
    valid = jnp.array([True, False, True])
    weights = es.pair_weights(scores, "centered_ranks", valid)
    assert float(weights[1]) == 0.0
    # the remaining four scores rank 0..3 exactly as if the dropped pair never existed
    np.testing.assert_allclose(weights[jnp.array([0, 2])], es.pair_weights(scores[jnp.array([0, 2])], "centered_ranks"))


@pytest.mark.parametrize("rank", [0, 2])
def test_update_in_chunk_parts_matches_the_one_function_gradient(rank):
    shapes = ((6, 5), (5,)) if rank else ((30,),)
    perturbation = es.Perturbation(shapes, rank)
    config = build_config("tiny", population=12, chunk_size=4, sigma=0.1, fitness_shaping="none",
                          perturbation_rank=rank)
    update = es.make_update(config, perturbation)
    scores = jnp.asarray(np.random.default_rng(0).normal(size=(12, 2)), jnp.float32)
    valid = jnp.array([True] * 4 + [False] * 4 + [True] * 4)  # the middle chunk was dropped
    weights, num_pairs = update.weights(scores, valid)
    weights = np.asarray(weights)
    parts = [update.part_here(7, weights, index) for index in range(3)]
    np.testing.assert_array_equal(parts[1], np.zeros(perturbation.parameter_size))
    reference = es.pseudo_gradient(es.iteration_key(7), jnp.asarray(weights), 0.1, perturbation, 4, num_pairs)
    gradient = es.GradientParts.total(parts) / (2 * 0.1 * int(num_pairs))
    np.testing.assert_allclose(gradient, reference, rtol=1e-5, atol=1e-6)
