import functools

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

from pizero_ray import es
from pizero_ray.config import build_config


def reference_gradient(key, weights, sigma, perturbation, num_pairs=None):
    """sum_i w_i z_i / (2 sigma n), every pair's full direction formed: what the chunked parts must add up to."""
    n = weights.shape[0]
    total = sum(float(weights[i]) * np.asarray(es.expand_noise(es.pair_noise(key, i, perturbation.noise_size),
                                                                perturbation), np.float64) for i in range(n))
    return total / (2.0 * sigma * (n if num_pairs is None else num_pairs))


@functools.lru_cache(maxsize=None)
def _directions(n, perturbation):
    """jit(key) -> [n, D]: each pair's es.expand_noise(es.pair_noise(key, i, ...)), formed in one program, not
    one eager call per pair (the ascent test forms 64 pairs' 30 times)."""
    direction = lambda key, i: es.expand_noise(es.pair_noise(key, i, perturbation.noise_size), perturbation)
    return jax.jit(lambda key: jax.vmap(direction, in_axes=(None, 0))(key, jnp.arange(n)))


def _quadratic_scores(theta, key, n, sigma, target, perturbation):
    noise = np.asarray(_directions(n, perturbation)(key))
    score = lambda x: -np.sum((x - target) ** 2, axis=-1)
    return np.stack([score(theta + sigma * noise), score(theta - sigma * noise)], axis=1).astype(np.float32)


def _tell_all_here(strategy, state, scores, valid, num_chunks):
    """One whole ES step in this process: every chunk's part regenerated, then tell."""
    seed = strategy.ask(state)
    weights = strategy.weights(scores, valid)
    parts = [strategy.parts.chunk_here(seed, weights, index) for index in range(num_chunks)]
    return strategy.tell(state, scores, valid, parts)


def test_ask_is_the_iteration_seed_and_tell_counts_the_iteration():
    config = build_config("tiny", population=4, chunk_size=2, seed=3)
    strategy = es.make_strategy(config, es.Perturbation(((5,),), 0))
    state = strategy.init(np.zeros(5, np.float32))
    assert state.iteration == 0 and strategy.ask(state) == es.iteration_seed(3, 0)
    scores = np.arange(8, dtype=np.float32).reshape(4, 2)
    state, stats = _tell_all_here(strategy, state, scores, np.ones(4, bool), 2)
    assert state.iteration == 1 and strategy.ask(state) == es.iteration_seed(3, 1)
    assert (stats.mean_score, stats.max_score, stats.min_score, stats.pairs) == (3.5, 7.0, 0.0, 4)
    assert stats.update_norm > 0 and stats.parameter_norm == pytest.approx(stats.update_norm, rel=1e-6)


@pytest.mark.parametrize("rank", [0, 2])
def test_the_chunked_parts_add_up_to_the_one_function_gradient(rank):
    shapes = ((6, 5), (5,)) if rank else ((30,),)
    perturbation = es.Perturbation(shapes, rank)
    config = build_config("tiny", population=12, chunk_size=4, sigma=0.1, fitness_shaping="none",
                          perturbation_rank=rank)
    strategy = es.make_strategy(config, perturbation)
    scores = np.random.default_rng(0).normal(size=(12, 2)).astype(np.float32)
    valid = np.array([True] * 4 + [False] * 4 + [True] * 4)  # the middle chunk was dropped
    weights = strategy.weights(scores, valid)
    parts = [strategy.parts.chunk_here(7, weights, index) for index in range(3)]
    np.testing.assert_array_equal(parts[1], np.zeros(perturbation.parameter_size))
    reference = reference_gradient(es.iteration_key(7), weights, 0.1, perturbation, num_pairs=8)
    gradient = es.GradientParts.total(parts) / (2 * 0.1 * 8)
    np.testing.assert_allclose(gradient, reference, rtol=1e-5, atol=1e-6)
    # tell divides by the pairs that came in: its gradient norm is the reference's
    state = strategy.init(np.zeros(perturbation.parameter_size, np.float32))
    _, stats = strategy.tell(state, scores, valid, parts)
    assert stats.gradient_norm == pytest.approx(float(np.linalg.norm(reference)), rel=1e-5)
    assert stats.pairs == 8


def test_a_population_that_ties_throughout_takes_no_step():
    config = build_config("tiny", population=8, chunk_size=4)
    strategy = es.make_strategy(config, es.Perturbation(((30,),), 0))
    state = strategy.init(np.linspace(-1, 1, 30).astype(np.float32))
    new_state, stats = _tell_all_here(strategy, state, np.zeros((8, 2), np.float32), np.ones(8, bool), 2)
    np.testing.assert_array_equal(np.asarray(new_state.theta), np.asarray(state.theta))
    assert stats.gradient_norm == 0.0 and new_state.iteration == 1


def test_the_antithetic_gradient_of_a_quadratic_points_uphill():
    size, n, sigma = 20, 200, 0.05
    perturbation = es.Perturbation(((size,),), 0)
    theta = np.zeros(size, np.float32)
    target = np.linspace(-1, 1, size).astype(np.float32)
    key = es.iteration_key(3)
    weights = es.pair_weights(jnp.asarray(_quadratic_scores(theta, key, n, sigma, target, perturbation)), "none")
    g = reference_gradient(key, weights, sigma, perturbation)
    true_gradient = 2 * (target - theta)
    assert g @ true_gradient / (np.linalg.norm(g) * np.linalg.norm(true_gradient)) > 0.7


@pytest.mark.parametrize("shaping, rank", [("none", 0), ("centered_ranks", 0), ("centered_ranks", 2)])
def test_adam_ascent_steps_climb_the_quadratic(shaping, rank):
    perturbation = es.Perturbation(((4, 6), (6,)) if rank else ((10,),), rank)
    size = perturbation.parameter_size
    config = build_config("tiny", population=64, chunk_size=16, sigma=0.05, learning_rate=0.05, fitness_shaping=shaping,
                          perturbation_rank=rank)
    strategy = es.make_strategy(config, perturbation)
    state = strategy.init(jnp.zeros(size))
    target = np.linspace(-1, 1, size).astype(np.float32)
    start = np.sum(target**2)
    for _ in range(30):
        key = es.iteration_key(np.uint32(strategy.ask(state)))
        scores = _quadratic_scores(np.asarray(state.theta), key, 64, 0.05, target, perturbation)
        state, _ = _tell_all_here(strategy, state, scores, np.ones(64, bool), 4)
    assert np.sum((np.asarray(state.theta) - target) ** 2) < 0.5 * start
    assert isinstance(state.opt_state[1][0], optax.ScaleByAdamState) and int(state.opt_state[1][0].count) == 30
    assert state.iteration == 30


def test_parts_from_kept_noise_and_from_regenerated_noise_are_the_same_bits():
    perturbation = es.Perturbation(((6, 5), (5,)), 2)
    config = build_config("tiny", population=8, chunk_size=4, perturbation_rank=2)
    parts = es.gradient_parts(config, perturbation)
    weights = np.linspace(-1, 1, 4).astype(np.float32)
    kept = parts.noise(np.uint32(9), np.int32(4))  # what a worker keeps from scoring chunk 1
    np.testing.assert_array_equal(parts.from_noise(weights, kept), parts.regenerated(9, 4, weights))
    everything = np.concatenate([np.zeros(4, np.float32), weights])
    np.testing.assert_array_equal(parts.chunk_here(9, everything, 1), parts.regenerated(9, 4, weights))
    assert jax.numpy.asarray(kept).shape == (4, perturbation.noise_size)


def test_the_step_size_follows_its_cosine_decay_then_stays_at_zero():
    """Adam's step on a constant gradient is about lr * sign(g): the decayed steps' sizes are the schedule's."""
    gradient = jnp.linspace(-1.0, 1.0, 6)
    sizes = {}
    for decay in (0, 3):
        optimizer = es.make_optimizer(build_config("tiny", learning_rate=0.05, lr_decay_iterations=decay))
        theta, sizes[decay] = jnp.zeros(6), []
        state = optimizer.init(theta)
        for _ in range(5):
            updates, state = optimizer.update(gradient, state, theta)
            sizes[decay].append(float(jnp.linalg.norm(updates)))
    np.testing.assert_allclose(np.array(sizes[3]) / np.array(sizes[0]), [1.0, 0.75, 0.25, 0.0, 0.0], atol=1e-6)


def test_a_constant_step_size_keeps_the_optimiser_state_checkpoints_have():
    """No schedule state without a decay, so the checkpoints of runs before the setting still restore."""
    theta = jnp.zeros(6)
    before = optax.chain(optax.add_decayed_weights(0.0), optax.adam(0.01)).init(theta)  # the optimiser until now
    constant = es.make_optimizer(build_config("tiny")).init(theta)
    decayed = es.make_optimizer(build_config("tiny", lr_decay_iterations=10)).init(theta)
    assert jax.tree.structure(constant) == jax.tree.structure(before)
    assert len(jax.tree.leaves(decayed)) == len(jax.tree.leaves(before)) + 1  # the schedule's step count


@pytest.mark.parametrize("shaping", ["centered_ranks", "none"])
def test_a_broken_members_score_never_reaches_the_parameters(shaping):
    config = build_config("tiny", population=4, chunk_size=2, fitness_shaping=shaping)
    strategy = es.make_strategy(config, es.Perturbation(((5,),), 0))
    state = strategy.init(np.zeros(5, np.float32))
    scores = np.array([[1, 2], [3, np.nan], [0.5, 0.2], [2, np.inf]], np.float32)
    state, stats = _tell_all_here(strategy, state, scores, np.ones(4, bool), 2)
    assert np.isfinite(np.asarray(state.theta)).all() and stats.update_norm > 0
    assert stats.non_finite_scores == 2
    assert (stats.max_score, stats.min_score, stats.mean_score) == pytest.approx((3.0, 0.2, 8.7 / 6))  # the finite six
