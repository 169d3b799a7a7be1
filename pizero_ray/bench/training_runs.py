"""The Ray trainer on the bench's work: iteration and update times, a new worker's first result, its traffic,
and a worker's peak memory."""

from __future__ import annotations

import statistics
import tempfile
from pathlib import Path

import numpy as np

from pizero_ray.bench.traffic import median_traffic, where_gradient_parts_form
from pizero_ray.config import Config


def train_briefly(config: Config, options, worker_factory=None, on_iteration=None) -> tuple[dict, list[dict]]:
    """The real trainer on ``config`` with ``options`` (``RunOptions``) in a throwaway run dir: (``driver.train``'s
    result, the metrics rows of its iterations)."""
    from pizero_ray.storage import run_dir
    from pizero_ray.trainer import driver

    with tempfile.TemporaryDirectory(prefix="pizero-bench-") as tmp:
        path = Path(tmp)
        run_dir.write_config(path, config)
        result = driver.train(path, config, options, on_iteration=on_iteration, worker_factory=worker_factory)
        return result, [row for row in run_dir.read_metrics(path) if row["iteration"] > 0]


def trainer(config: Config, workers: int, iterations: int, cache_dir: str, cpus_per_worker: int = 1,
            gpus_per_worker: float = 0.0, gradient_on: str = "auto") -> dict:
    """A short training run: median iteration and update time, first-result latency, bytes each way.

    ``gradient_on`` is the run's ``--gradient-on``; the result says where it resolved to.
    """
    from pizero_ray.trainer.options import RunOptions

    options = RunOptions.create(iterations=iterations, workers=workers, cpus_per_worker=cpus_per_worker,
                                gpus_per_worker=gpus_per_worker, checkpoint_every=0, compile_cache=cache_dir,
                                gradient_on=gradient_on)
    _, rows = train_briefly(config, options)
    # The first iterations wait for the workers' start and, on a worker with
    # several devices, for its other devices' compiles: the last half is steady.
    steady = rows[len(rows) // 2:]
    first = rows[0].get("new_worker_first_result_s", [])
    return {
        "workers": workers,
        "iteration_s": statistics.median(row["iteration_time_s"] for row in steady),
        "update_s": statistics.median(row["update_time_s"] for row in steady),
        "worker_first_result_s": max(first) if first else None,
        "gradient_on": where_gradient_parts_form(config, options.pool),
        # measured: the chunks whose part the driver formed itself (all of them where parts form on the driver)
        "gradient_parts_on_driver": statistics.median(row["gradient_parts_on_driver"] for row in steady),
        **median_traffic(steady),
    }


def worker_memory(config: Config, cache_dir: str) -> float:
    """Peak resident memory (MB) of one Ray worker actor after evaluating a whole iteration."""
    import ray

    from pizero_ray import envs, es
    from pizero_ray.es import population
    from pizero_ray.trainer import workers

    theta, _ = population.flat_params(config, envs.make(config.env, **config.env_kwargs()))
    actor = workers.start_worker(config.to_json(), 1.0, 0.0, cache_dir)
    try:
        ray.get(actor.ready.remote(), timeout=600)
        theta_ref = ray.put(np.asarray(theta))
        seed = es.iteration_seed(config.seed, 1)
        ray.get([actor.score_chunk.remote(theta_ref, seed, start)
                 for start in range(0, config.population, config.chunk_size)], timeout=600)
        return ray.get(actor.peak_rss_mb.remote(), timeout=60)
    finally:
        ray.kill(actor)
