"""Means across seeds with 95% confidence bands by the bootstrap's BCa method, as in the paper's figures.

Pure NumPy/SciPy. The bootstrap's resampling is seeded, so a figure redrawn
from the same runs is the same figure.
"""

from __future__ import annotations

import warnings

import numpy as np

CONFIDENCE = 0.95
RESAMPLES = 9999
BOOTSTRAP_SEED = 0


def bca_interval(values, confidence: float = CONFIDENCE, resamples: int = RESAMPLES,
                 seed: int = BOOTSTRAP_SEED) -> tuple[float, float]:
    """The BCa bootstrap interval of the mean of ``values`` (``scipy.stats.bootstrap(..., method="BCa")``).

    Degenerate samples have no spread to resample: one value, or all equal,
    give (mean, mean). Where BCa's acceleration is undefined scipy returns
    NaN; so does this (no band is drawn rather than a made-up one).
    """
    from scipy import stats

    values = np.asarray(values, dtype=np.float64)
    if values.ndim != 1 or values.size == 0:
        raise ValueError(f"bca_interval needs a non-empty 1-d sample, got shape {values.shape}")
    mean = float(values.mean())
    if values.size == 1 or np.all(values == values[0]):
        return mean, mean
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # scipy warns (and returns NaN) where BCa is undefined
        result = stats.bootstrap((values,), np.mean, confidence_level=confidence, n_resamples=resamples,
                                 method="BCa", random_state=np.random.default_rng(seed))
    return float(result.confidence_interval.low), float(result.confidence_interval.high)


def curve_at(times: np.ndarray, scores: np.ndarray, grid: np.ndarray) -> np.ndarray:
    """A run's evaluated score at each ``grid`` time: its first evaluation at or after it (NaN if none).

    The driver evaluates at the first iteration ending after each mark of
    ``--eval-every-minutes``, so that evaluation is the run's score "at" the mark.
    """
    order = np.argsort(times, kind="stable")
    times, scores = np.asarray(times, dtype=np.float64)[order], np.asarray(scores, dtype=np.float64)[order]
    index = np.searchsorted(times, grid, side="left")
    out = np.full(grid.shape, np.nan)
    found = index < times.size
    out[found] = scores[index[found]]
    return out


def mean_band(curves: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(mean, low, high) across seeds (rows) at each time (columns), NaN where a seed has no score yet."""
    curves = np.asarray(curves, dtype=np.float64)
    mean, low, high = (np.full(curves.shape[1], np.nan) for _ in range(3))
    for column in range(curves.shape[1]):
        values = curves[:, column]
        if np.isnan(values).any():
            continue
        mean[column] = values.mean()
        low[column], high[column] = bca_interval(values)
    return mean, low, high
