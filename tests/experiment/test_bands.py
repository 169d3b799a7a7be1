"""BCa bands, checked against scipy on fixed data, and the curves on the wall-clock grid."""

import numpy as np
import pytest
from scipy import stats

from pizero_ray.experiment import bands

FIXED = np.array([2.91, 2.95, 3.02, 2.88, 3.40])  # five seeds' final scores, one far out


def test_bca_interval_is_scipys_bca_on_fixed_data():
    expected = stats.bootstrap((FIXED,), np.mean, confidence_level=0.95, n_resamples=9999, method="BCa",
                               random_state=np.random.default_rng(0)).confidence_interval
    low, high = bands.bca_interval(FIXED)
    assert (low, high) == pytest.approx((expected.low, expected.high), abs=1e-12)
    # BCa, not the percentile interval: the outlier skews it upwards, away from the symmetric one
    percentile = stats.bootstrap((FIXED,), np.mean, n_resamples=9999, method="percentile",
                                 random_state=np.random.default_rng(0)).confidence_interval
    assert (low, high) != pytest.approx((percentile.low, percentile.high), abs=1e-4)
    assert low < FIXED.mean() < high
    assert high - FIXED.mean() > FIXED.mean() - low


def test_bca_interval_of_a_large_normal_sample_is_close_to_the_t_interval():
    sample = np.random.default_rng(1).normal(10.0, 2.0, size=400)
    low, high = bands.bca_interval(sample)
    t_low, t_high = stats.t.interval(0.95, sample.size - 1, loc=sample.mean(), scale=stats.sem(sample))
    assert low == pytest.approx(t_low, abs=0.05) and high == pytest.approx(t_high, abs=0.05)


def test_degenerate_samples_have_a_zero_width_band_and_bad_shapes_an_error():
    assert bands.bca_interval([3.0]) == (3.0, 3.0)
    assert bands.bca_interval([-1.5, -1.5, -1.5]) == (-1.5, -1.5)
    with pytest.raises(ValueError, match=r"shape \(0,\)"):
        bands.bca_interval([])


def test_curve_at_takes_the_first_evaluation_at_or_after_each_mark():
    times = np.array([0.0, 61.0, 119.0, 125.0, 183.0])
    scores = np.array([1.0, 2.0, 3.0, 4.0, 5.0])
    marks = np.array([0.0, 60.0, 120.0, 180.0, 240.0])
    assert bands.curve_at(times, scores, marks) == pytest.approx([1.0, 2.0, 4.0, 5.0, np.nan], nan_ok=True)


def test_mean_band_per_mark_and_nan_where_a_seed_has_no_score():
    curves = np.array([[1.0, 2.0, np.nan], [3.0, 2.0, 5.0], [2.0, 2.0, 6.0]])
    mean, low, high = bands.mean_band(curves)
    assert mean[:2] == pytest.approx([2.0, 2.0]) and np.isnan(mean[2])
    assert (low[0], high[0]) == pytest.approx(bands.bca_interval([1.0, 3.0, 2.0]))
    assert low[1] == high[1] == 2.0
