"""`pizero bench --scale`: the trainer's own costs as workers, chunks and parameters grow.

The real driver (``trainer.driver.train``) and the real ``WorkerPool`` run
against stub workers (``bench.stub_workers``) whose chunks take a modelled
delay, chosen so that every point's rollout would take ``IDEAL_COMPUTE_S`` if
the driver cost nothing. Per point it records the driver process's own CPU
seconds per iteration (scheduling, collecting, the update, Ray's threads in
it), the iteration's wall time, the bytes each way (the pool's count), the
object store's use, and the efficiency: the modelled compute over the
iteration time. Points whose processes would not fit this machine stand in:
at most ``MAX_PROCESSES`` stub processes serve the pool's workers.

Beyond what runs here (hundreds of parameters megabytes, 64 nodes), the unit
costs of ``scale_costs`` feed ``scale_model``.
"""

from __future__ import annotations

import math
import statistics
import tempfile
import time
from pathlib import Path

IDEAL_COMPUTE_S = 0.5  # an iteration's rollout, were the driver free
PAIRS_PER_CHUNK = 2  # small chunks: up to 4,096 of them without the population's own arithmetic dominating
MAX_PROCESSES = 16  # stub processes at most; more workers stand in on them
SWEEP_WORKERS = (1, 8, 32, 128, 512)
SWEEP_CHUNKS = (64, 512, 4096)
DESIGNS = {  # today's design (a), its two ways of forming the gradient
    "a_parts_on_driver": {"perturbation_rank": 1, "gradient_on": "driver"},
    "a_parts_on_workers": {"perturbation_rank": 0, "gradient_on": "workers"},
}
MEASURED_ITERATIONS = 4  # the first (workers starting, compiles) is not counted


def chunk_delay_s(workers: int, chunks: int) -> float:
    """The stub's delay per chunk: ``IDEAL_COMPUTE_S`` for the iteration in ceil(chunks / workers) waves."""
    return IDEAL_COMPUTE_S / math.ceil(chunks / workers)


def object_store_bytes() -> int:
    """The plasma stores' use, all nodes, as Ray's memory summary states it."""
    import re

    from ray._private import internal_api

    summary = internal_api.memory_summary(stats_only=True)
    found = re.search(r"Plasma memory usage (\d+) MiB", summary)
    return int(found.group(1)) * 2**20 if found else -1


def sweep_point(workers: int, chunks: int, design: str) -> dict:
    """The real driver for ``MEASURED_ITERATIONS`` iterations against stub workers; medians of the steady ones."""
    from pizero_ray.bench.plans import bench_config
    from pizero_ray.bench.stub_workers import StubWorkers
    from pizero_ray.storage import run_dir
    from pizero_ray.trainer import driver

    settings = DESIGNS[design]
    config = bench_config(chunks * PAIRS_PER_CHUNK, PAIRS_PER_CHUNK, perturbation_rank=settings["perturbation_rank"])
    stubs = StubWorkers(PAIRS_PER_CHUNK, _parameters(config), chunk_delay_s(workers, chunks),
                        processes=None if workers <= MAX_PROCESSES else MAX_PROCESSES)
    driver_cpu, store = [], []
    clock = {"cpu": time.process_time()}

    def on_iteration(row):
        now = time.process_time()
        driver_cpu.append(now - clock["cpu"])
        if row["iteration"] == MEASURED_ITERATIONS:
            store.append(object_store_bytes())
        clock["cpu"] = time.process_time()  # the memory summary is the bench's, not the driver's

    with tempfile.TemporaryDirectory(prefix="pizero-scale-") as tmp:
        path = Path(tmp)
        run_dir.write_config(path, config)
        options = driver.RunOptions.create(iterations=MEASURED_ITERATIONS, workers=workers, checkpoint_every=0,
                                           gradient_on=settings["gradient_on"], compile_cache="none")
        try:
            driver.train(path, config, options, on_iteration=on_iteration, worker_factory=stubs.factory())
        finally:
            stubs.shutdown()
        rows = [row for row in run_dir.read_metrics(path) if row["iteration"] > 1]
    return _point_row(workers, chunks, design, config, rows, driver_cpu[1:], store)


def _parameters(config) -> int:
    import envs
    from pizero_ray.es import population

    return population.params_layout(config, envs.make(config.env, **config.env_kwargs())).size


def _point_row(workers, chunks, design, config, rows, driver_cpu, store) -> dict:
    iteration_s = statistics.median(row["iteration_time_s"] for row in rows)
    return {
        "workers": workers, "chunks": chunks, "parameters": _parameters(config), "design": design,
        "source": "measured", "stand_ins": workers > MAX_PROCESSES,
        "driver_s": statistics.median(driver_cpu), "iteration_s": iteration_s,
        "update_s": statistics.median(row["update_time_s"] for row in rows),
        "bytes_to_workers": int(statistics.median(row["bytes_to_workers"] for row in rows)),
        "bytes_to_driver": int(statistics.median(row["bytes_from_workers"] for row in rows)),
        "object_store_bytes": store[0] if store else -1,
        "efficiency": IDEAL_COMPUTE_S / iteration_s,
    }


def sweep(points, progress=print) -> list[dict]:
    rows = []
    for workers, chunks, design in points:
        progress(f"scale: {workers} workers, {chunks} chunks, {design}")
        rows.append(sweep_point(workers, chunks, design))
    return rows


def default_points() -> list[tuple[int, int, str]]:
    """Every (workers, chunks) with the parts on the driver; with parts on the workers, up to 512 chunks (4,096
    parts of the bench agent's 54,279 floats would be 0.9 GB an iteration through this machine's stores)."""
    points = [(w, c, "a_parts_on_driver") for w in SWEEP_WORKERS for c in SWEEP_CHUNKS]
    return points + [(w, c, "a_parts_on_workers") for w in SWEEP_WORKERS for c in SWEEP_CHUNKS if c <= 512]
