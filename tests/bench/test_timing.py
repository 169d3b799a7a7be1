"""Rollouts compared in one run take turns, so a slow spell of a shared machine hits them all alike."""

from pizero_ray.bench.timing import CompiledRollout, time_interleaved
from pizero_ray.config import build_config


def test_repeats_of_the_rollouts_are_interleaved():
    calls = []

    def timed(name):
        def one_iteration(seed):
            calls.append((name, seed))
            return 1.0
        return CompiledRollout(build_config("tiny"), one_iteration, 0.0, 10, 80, 1)

    results = time_interleaved({"a": timed("a"), "b": timed("b")}, repeats=2)
    assert calls == [("a", 1), ("b", 1), ("a", 2), ("b", 2)]  # seed 0 is the compile's warm-up
    assert set(results) == {"a", "b"}
