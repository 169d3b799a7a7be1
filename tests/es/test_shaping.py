import jax.numpy as jnp
import numpy as np
import pytest

from pizero_ray import es


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


def test_dropped_pairs_take_no_rank_and_no_weight():
    scores = jnp.array([[1.0, 2.0], [100.0, -100.0], [3.0, 0.0]])
    valid = jnp.array([True, False, True])
    weights = es.pair_weights(scores, "centered_ranks", valid)
    assert float(weights[1]) == 0.0
    # the remaining four scores rank 0..3 exactly as if the dropped pair never existed
    np.testing.assert_allclose(weights[jnp.array([0, 2])], es.pair_weights(scores[jnp.array([0, 2])], "centered_ranks"))


def test_a_population_that_ties_throughout_gives_zero_weights():
    scores = jnp.zeros((8, 2))  # every member covers 0 goals, as early in Sokoban
    np.testing.assert_array_equal(es.pair_weights(scores, "centered_ranks"), np.zeros(8))
    valid = jnp.array([True] * 6 + [False] * 2)
    np.testing.assert_array_equal(es.pair_weights(scores, "centered_ranks", valid), np.zeros(8))

