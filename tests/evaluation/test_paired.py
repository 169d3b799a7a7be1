"""Paired comparisons: hand-checked differences and shares, the degenerate interval, and why pairing matters."""

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from pizero_ray.evaluation.paired import compare_scores

REPO = str(Path(__file__).resolve().parents[2])


def test_means_difference_and_shares_by_hand():
    result = compare_scores([3.0, 1.0, 2.0, 2.0], [1.0, 2.0, 2.0, 0.0])  # differences 2, -1, 0, 2
    assert (result.mean_a, result.mean_b, result.mean_difference) == (2.0, 1.25, 0.75)
    assert (result.a_higher, result.tied, result.b_higher) == (0.5, 0.25, 0.25)


def test_the_same_agent_twice_differs_by_exactly_zero_and_ties_everywhere():
    scores = np.random.default_rng(0).normal(size=100)
    result = compare_scores(scores, scores.copy())
    assert result.mean_difference == 0.0 and result.interval == (0.0, 0.0)
    assert (result.a_higher, result.tied, result.b_higher) == (0.0, 1.0, 0.0)


def test_a_constant_difference_is_exactly_d_both_ends():
    a, b = np.full(1000, 0.1), np.zeros(1000)
    assert np.mean(a - b) != 0.1  # the float64 mean of 1,000 copies of 0.1 misses it by a bit
    result = compare_scores(a, b)
    assert result.mean_difference == 0.1 and result.interval == (0.1, 0.1)
    assert result.a_higher == 1.0


def test_the_interval_is_scipys_bca_of_the_differences_seeded():
    rng = np.random.default_rng(2)
    a, b = rng.normal(size=50), rng.normal(size=50)
    expected = stats.bootstrap((a - b,), np.mean, confidence_level=0.95, n_resamples=9999, method="BCa",
                               random_state=np.random.default_rng(7)).confidence_interval
    result = compare_scores(a, b, seed=7)
    assert result.interval == pytest.approx((expected.low, expected.high), abs=1e-12)
    assert compare_scores(a, b, seed=7).interval == result.interval  # the same seed, the same interval
    assert compare_scores(a, b, seed=8).interval != result.interval  # the seed is what fixes it


def test_a_clear_shift_excludes_zero_where_side_by_side_intervals_overlap():
    """Episodes vary far more than the agents do: B's score is the episode's, A's 0.2 more, give or take 0.1."""
    rng = np.random.default_rng(1)
    episode = rng.normal(0.0, 1.0, size=200)
    a, b = episode + 0.2 + rng.normal(0.0, 0.1, size=200), episode
    half = lambda x: 1.96 * x.std(ddof=1) / np.sqrt(x.size)
    assert a.mean() - half(a) < b.mean() + half(b)  # eval's side-by-side intervals overlap ...
    result = compare_scores(a, b)
    low, high = result.interval
    assert 0.0 < low < 0.2 < high  # ... the paired interval excludes 0 and holds the shift
    assert result.a_higher > 0.9


def test_scores_that_are_not_one_per_episode_alike_are_an_error_naming_the_shapes():
    with pytest.raises(ValueError, match=r"shapes \(3,\) and \(2,\)"):
        compare_scores([1.0, 2.0, 3.0], [1.0, 2.0])
    with pytest.raises(ValueError, match=r"shapes \(0,\) and \(0,\)"):
        compare_scores([], [])


def test_the_math_imports_neither_jax_nor_ray():
    code = ("import json, sys, pizero_ray.evaluation.paired as p; p.compare_scores([1.0, 2.0], [0.0, 2.5]); "
            "print(json.dumps(sorted({m.split('.')[0] for m in sys.modules})))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         env={"PATH": "/usr/bin:/bin", "PYTHONPATH": REPO})
    loaded = set(json.loads(out.stdout))
    assert "scipy" in loaded  # the check sees real imports
    assert not {"jax", "ray"} & loaded
