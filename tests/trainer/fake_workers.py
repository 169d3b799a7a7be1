"""Light fake worker actors (no JAX) for the pool's and the driver's tests: they answer at once unless told."""

from __future__ import annotations

from typing import Callable

import numpy as np


def untied_scores(seed: int, first_pair: int, chunk: int) -> np.ndarray:
    """Scores [chunk, 2] with no ties: with ties every weight would be 0 and no part would be asked of a worker."""
    pairs = np.arange(first_pair, first_pair + chunk, dtype=np.float32)
    return np.stack([pairs, -pairs], axis=1)


def use(monkeypatch, config, hang_on=None, part_delay_s: float = 0.0, sigterm_on_seed=None,
        scores: Callable[[int, int, int], np.ndarray] = untied_scores, hang_once_on=None,
        start_delay_s: Callable[[int], float] = lambda number: 0.0, started_dir: str | None = None) -> None:
    """The pool's workers become fakes: ``scores(seed, first pair, chunk size)`` for each chunk, zero parts.

    ``hang_on``: (seed, first pair) of a chunk that never finishes; ``hang_once_on``: one that
    never finishes on the first worker handed it, and finishes on the next; ``part_delay_s``:
    how long ``gradient_part`` takes; ``sigterm_on_seed``: ``gradient_part`` of that
    seed first sends SIGTERM to this (the driver's) process, once, then hangs.
    ``start_delay_s(n)``: how long the n-th worker started (from 0) takes in ``__init__``;
    ``started_dir``: each worker writes a file there as its ``__init__`` begins. Workers
    ask Ray for the custom resources the pool asks for (``--worker-resources``), no CPUs.
    """
    import itertools
    import os
    import tempfile

    from pizero_ray import envs
    from pizero_ray.es import population
    from pizero_ray.trainer import workers

    chunk = config.chunk_size
    size = population.flat_params(config, envs.make(config.env))[1].size
    driver_pid = os.getpid()
    markers = tempfile.mkdtemp(prefix="pizero-fake-markers-")
    signalled, hung_once = os.path.join(markers, "sent"), os.path.join(markers, "hung")

    class FakeWorker:  # defined in a function: Ray pickles it by value
        def __init__(self, start_delay_s: float = 0.0):
            import os
            import time
            if started_dir is not None:
                open(os.path.join(started_dir, str(os.getpid())), "w").close()
            time.sleep(start_delay_s)

        def ready(self):
            import os

            import ray
            return {"pid": os.getpid(), "node_id": ray.get_runtime_context().get_node_id(), "devices": 1}

        def score_chunk(self, theta, seed, first_pair):
            import os
            import time
            if (seed, first_pair) == hang_on:
                time.sleep(3600)
            if (seed, first_pair) == hang_once_on:
                try:  # the first worker handed the chunk hangs on it; the next one answers
                    os.close(os.open(hung_once, os.O_CREAT | os.O_EXCL))
                    time.sleep(3600)
                except FileExistsError:
                    pass
            return scores(seed, first_pair, chunk)

        def score_chunks(self, theta, seed, first_pairs):
            return [self.score_chunk(theta, seed, first_pair) for first_pair in first_pairs]

        def gradient_part(self, seed, first_pair, weights):
            import os
            import signal
            import time

            import numpy as np
            if seed == sigterm_on_seed:
                try:  # one SIGTERM in all, whichever chunk's part comes first: a second one means "hurry"
                    os.close(os.open(signalled, os.O_CREAT | os.O_EXCL))
                    os.kill(driver_pid, signal.SIGTERM)
                except FileExistsError:
                    pass
                time.sleep(3600)
            time.sleep(part_delay_s)
            return np.zeros(size, np.float32)

        def gradient_parts(self, seed, first_pairs, weights):
            return [self.gradient_part(seed, first_pair, row) for first_pair, row in zip(first_pairs, weights)]

    numbers = itertools.count()

    def start_worker(config_json, num_cpus, num_gpus, compile_cache_dir, resources=None, *args, **kwargs):
        import ray
        return ray.remote(FakeWorker).options(num_cpus=0, max_concurrency=2, resources=resources or {}).remote(
            start_delay_s(next(numbers)))

    monkeypatch.setattr(workers, "start_worker", start_worker)
