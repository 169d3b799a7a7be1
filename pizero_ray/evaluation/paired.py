"""Two agents on the same episodes: the paired differences, their BCa interval, and who scored higher how often.

Pure NumPy/SciPy (no JAX, no Ray). Each episode is played by both agents, so
the difference on one episode holds the episode fixed: what is left is how
the agents differ, not how episodes do. The bootstrap is seeded, so the same
scores give the same interval.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from pizero_ray.experiment.bands import bca_interval


class PairedComparison(NamedTuple):
    """A against B on the same episodes; the shares add up to 1."""

    mean_a: float
    mean_b: float
    mean_difference: float  # the mean over episodes of A's score minus B's
    interval: tuple[float, float]  # 95% BCa bootstrap interval of mean_difference
    a_higher: float  # share of episodes where A scored higher
    tied: float
    b_higher: float


def paired_scores(scores_a, scores_b) -> tuple[np.ndarray, np.ndarray]:
    """Both score vectors as float64, checked to be one score per episode, the same episodes, in the same order."""
    a, b = np.asarray(scores_a, dtype=np.float64), np.asarray(scores_b, dtype=np.float64)
    if a.ndim != 1 or a.shape != b.shape or a.size == 0:
        raise ValueError(f"paired scores need two non-empty 1-d arrays of one length, got shapes {a.shape} "
                         f"and {b.shape}")
    return a, b


def compare_scores(scores_a, scores_b, seed: int = 0) -> PairedComparison:
    """A's and B's scores on the same episodes (episode i of each is the same episode), compared pairwise.

    A constant difference d (the same agent twice: d = 0) has no spread to
    resample: its interval is exactly (d, d), and its mean exactly d.
    """
    a, b = paired_scores(scores_a, scores_b)
    differences = a - b
    if np.all(differences == differences[0]):
        mean_difference = float(differences[0])  # a float64 mean of n copies of d need not be d to the last bit
        interval = (mean_difference, mean_difference)
    else:
        mean_difference = float(differences.mean())
        interval = bca_interval(differences, seed=seed)
    return PairedComparison(
        mean_a=float(a.mean()), mean_b=float(b.mean()), mean_difference=mean_difference, interval=interval,
        a_higher=float(np.mean(differences > 0)), tied=float(np.mean(differences == 0)),
        b_higher=float(np.mean(differences < 0)))
