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



@pytest.mark.parametrize("broken", [np.nan, np.inf, -np.inf])
def test_a_non_finite_score_ranks_below_every_finite_one(broken):
    """NaN sorts after +inf: left as it was, the pair (3, NaN) got weight -0.14, its broken member the best."""
    scores = jnp.array([[1.0, 2.0], [3.0, broken], [0.5, 0.2], [2.0, 1.0]])
    ranks = np.asarray(es.centered_ranks(scores))
    assert ranks[1, 1] == -0.5 and (np.delete(ranks.reshape(-1), 3) > -0.5).all()  # alone at the lowest rank
    weights = np.asarray(es.pair_weights(scores, "centered_ranks"))
    assert np.isfinite(weights).all() and weights[1] == weights.max() > 0  # the pair steps towards +z
    np.testing.assert_array_equal(weights, es.pair_weights(scores.at[1, 1].set(-10.0), "centered_ranks"))


def test_non_finite_scores_tie_for_the_lowest_rank_and_a_dropped_pair_still_takes_none():
    scores = jnp.array([[np.nan, -np.inf], [1.0, 2.0], [np.nan, 0.0], [5.0, 5.0]])
    valid = jnp.array([True, True, True, False])
    weights = np.asarray(es.pair_weights(scores, "centered_ranks", valid))
    assert weights[0] == 0.0 and weights[3] == 0.0  # two broken members tie; the dropped pair weighs nothing
    assert weights[2] < 0 and np.isfinite(weights).all()


def test_raw_scores_count_a_non_finite_one_as_the_lowest_finite_score():
    scores = jnp.array([[1.0, 2.0], [3.0, np.nan], [0.5, 0.2], [2.0, -np.inf]])
    weights = np.asarray(es.pair_weights(scores, "none"))
    np.testing.assert_allclose(weights, [-1.0, 3.0 - 0.2, 0.3, 2.0 - 0.2], rtol=1e-6)
    assert np.isfinite(weights).all()
    all_broken = np.asarray(es.pair_weights(jnp.full((3, 2), np.nan), "none"))
    np.testing.assert_array_equal(all_broken, np.zeros(3))  # nothing to learn from: no step


def test_difference_ranks_see_each_pairs_comparison_not_its_episodes_difficulty():
    from pizero_ray.es.shaping import pair_weights

    scores = np.array([[5.0, 4.0], [-10.0, -7.0], [100.0, 100.0], [0.5, 0.0]], np.float32)
    weights = np.asarray(pair_weights(scores, "difference_ranks"))
    # d = +1, -3, 0, +0.5: signs kept, |d| ranked 1..4 (0 < 0.5 < 1 < 3), scaled by the pairs
    np.testing.assert_allclose(weights, [3 / 4, -4 / 4, 1 / 4 * 0, 2 / 4])
    harder = scores + np.array([[1000.0], [-50.0], [3.0], [-2.0]], np.float32)  # each pair's episodes easier/harder
    np.testing.assert_array_equal(np.asarray(pair_weights(harder, "difference_ranks")), weights)
    np.testing.assert_array_equal(np.asarray(pair_weights(scores * 1000.0, "difference_ranks")), weights)
    centred = np.asarray(pair_weights(harder, "centered_ranks"))
    assert not np.array_equal(centred, np.asarray(pair_weights(scores, "centered_ranks")))  # which ranks all 2N


def test_difference_ranks_weigh_pairs_not_valid_and_broken_scores_as_documented():
    from pizero_ray.es.shaping import pair_weights

    scores = np.array([[1.0, 0.0], [np.nan, 2.0], [3.0, 1.0]], np.float32)
    weights = np.asarray(pair_weights(scores, "difference_ranks", valid=np.array([True, True, False])))
    assert weights[2] == 0.0  # not valid: no weight
    assert weights[1] < 0 < weights[0]  # NaN counts as the lowest score: its member lost
