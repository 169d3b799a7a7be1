"""The determinism guarantee, shown: a clean run and one whose workers are SIGKILLed mid-iteration, compared.

Both runs train the same config for the same iterations; the parameters they
end with must hash the same.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Callable

import numpy as np

from pizero_ray.config import Config
from pizero_ray.storage import run_dir as rundir
from pizero_ray.trainer import driver
from pizero_ray.trainer.options import RunOptions

RUN_NAMES = ("clean", "chaos")  # the two run dirs, under the base dir


def kill_schedule(seed: int, kills: int, iterations: int, num_chunks: int) -> frozenset[tuple[int, int]]:
    """``kills`` distinct (iteration, chunk) pairs drawn from ``seed`` (all of them if there are fewer)."""
    # Kills fall on random (iteration, chunk) pairs: right after that chunk is handed out,
    # the worker holding it is SIGKILLed (on this machine; a remote worker's actor is killed).
    rng = np.random.default_rng(seed)
    slots = iterations * num_chunks
    chosen = rng.choice(slots, size=min(kills, slots), replace=False)
    return frozenset((int(s) // num_chunks, int(s) % num_chunks) for s in chosen)


def compare_runs(base: Path, config: Config, options: RunOptions, kills: int, seed: int,
                 on_run: Callable[[str, Path], None] | None = None) -> dict:
    """Trains ``base/clean`` as ``options`` say and ``base/chaos`` with ``kills`` workers killed, then compares.

    ``on_run(name, path)`` is told as each run starts. Returns {"iterations",
    "workers_killed", "clean_parameter_hash", "chaos_parameter_hash",
    "identical"}.
    """
    schedule = kill_schedule(seed, kills, options.iterations, config.num_chunks)
    chaos_options = dataclasses.replace(options, pool=dataclasses.replace(options.pool, kill_schedule=schedule))
    results = {}
    for name, run_options in zip(RUN_NAMES, (options, chaos_options)):
        path = base / name
        rundir.write_config(path, config)
        if on_run is not None:
            on_run(name, path)
        results[name] = driver.train(path, config, run_options)
    return {
        "iterations": options.iterations,
        "workers_killed": results["chaos"]["workers_killed"],
        "clean_parameter_hash": results["clean"]["parameter_hash"],
        "chaos_parameter_hash": results["chaos"]["parameter_hash"],
        "identical": results["clean"]["parameter_hash"] == results["chaos"]["parameter_hash"],
    }
