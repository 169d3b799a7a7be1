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
import time

IDEAL_COMPUTE_S = 0.5  # an iteration's rollout, were the driver free
PAIRS_PER_CHUNK = 2  # small chunks: up to 4,096 of them without the population's own arithmetic dominating
MAX_PROCESSES = 16  # stub processes at most; more workers stand in on them
SWEEP_WORKERS = (1, 8, 32, 128, 512)
SWEEP_CHUNKS = (64, 512, 4096)
DESIGNS = {  # today's design (a), its two ways of forming the gradient, and the first with 8 chunks a call
    "a_parts_on_driver": {"perturbation_rank": 1, "gradient_on": "driver", "chunks_per_call": 1},
    "a_parts_on_workers": {"perturbation_rank": 0, "gradient_on": "workers", "chunks_per_call": 1},
    "a_parts_on_driver_8_per_call": {"perturbation_rank": 1, "gradient_on": "driver", "chunks_per_call": 8},
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
    from pizero_ray.trainer.options import RunOptions

    settings = DESIGNS[design]
    config = bench_config(chunks * PAIRS_PER_CHUNK, PAIRS_PER_CHUNK, perturbation_rank=settings["perturbation_rank"])
    parameters = _parameters(config)
    stubs = StubWorkers(PAIRS_PER_CHUNK, parameters, chunk_delay_s(workers, chunks),
                        processes=None if workers <= MAX_PROCESSES else MAX_PROCESSES)
    driver_cpu, store = [], []
    clock = {"cpu": time.process_time()}

    def on_iteration(row):
        now = time.process_time()
        driver_cpu.append(now - clock["cpu"])
        if row["iteration"] == MEASURED_ITERATIONS:
            store.append(object_store_bytes())
        clock["cpu"] = time.process_time()  # the memory summary is the bench's, not the driver's

    options = RunOptions.create(iterations=MEASURED_ITERATIONS, workers=workers, checkpoint_every=0,
                                gradient_on=settings["gradient_on"], compile_cache="none",
                                chunks_per_call=settings["chunks_per_call"])
    _, rows = _against_stubs(config, options, stubs, on_iteration)
    point = {"workers": workers, "chunks": chunks, "parameters": parameters, "design": design}
    return _point_row(point, rows, driver_cpu[1:], store)


def _against_stubs(config, options, stubs, on_iteration=None) -> tuple[dict, list[dict]]:
    """``train_briefly`` with ``stubs`` for workers (ended after): the result, and the rows after the first
    (which starts the workers)."""
    from pizero_ray.bench.training_runs import train_briefly

    try:
        result, rows = train_briefly(config, options, stubs.factory(), on_iteration)
    finally:
        stubs.shutdown()
    return result, [row for row in rows if row["iteration"] > 1]


def _parameters(config) -> int:
    from pizero_ray import envs
    from pizero_ray.es import population

    return population.params_layout(config, envs.make(config.env, **config.env_kwargs())).size


def _point_row(point: dict, rows, driver_cpu, store) -> dict:
    from pizero_ray.bench.traffic import median_traffic

    iteration_s = statistics.median(row["iteration_time_s"] for row in rows)
    traffic = median_traffic(rows)
    return {
        **point, "source": "measured", "stand_ins": point["workers"] > MAX_PROCESSES,
        "driver_s": statistics.median(driver_cpu), "iteration_s": iteration_s,
        "update_s": statistics.median(row["update_time_s"] for row in rows),
        "bytes_to_workers": int(traffic["bytes_to_workers"]), "bytes_to_driver": int(traffic["bytes_from_workers"]),
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
    """The sweep within about ten minutes here. With the parts on the driver: every worker count at 64 and 512
    chunks, and 4,096 chunks at 8 and 512 workers (about a minute each). With the parts on the workers: up to
    512 chunks (4,096 parts of 54,279 floats would be 0.9 GB an iteration through this machine's stores)."""
    points = [(w, c, "a_parts_on_driver") for w in SWEEP_WORKERS for c in SWEEP_CHUNKS[:2]]
    points += [(w, SWEEP_CHUNKS[2], design) for design in ("a_parts_on_driver", "a_parts_on_driver_8_per_call")
               for w in (8, 512)]
    return points + [(w, c, "a_parts_on_workers") for w in (1, 32, 512) for c in SWEEP_CHUNKS[:2]]


# ---------------------------------------------------------------- faults at scale

FAULT_WORKERS = 96  # stub processes of their own (a kill ends a real process): about 6 GB of this machine's 24
FAULT_ITERATIONS = 5
FAULT_CHUNKS = 2 * FAULT_WORKERS


def faults(workers: int = FAULT_WORKERS, iterations: int = FAULT_ITERATIONS, progress=print) -> dict:
    """A tenth of the workers SIGKILLed mid-iteration, every iteration, against the same run without kills.

    Stub workers with processes of their own, the parts on the driver, and a
    modelled rollout of ``IDEAL_COMPUTE_S``: the final parameters must be the
    clean run's, and the difference in iteration time is what the kills cost.
    """
    from pizero_ray.trainer.chaos import kill_schedule

    kills = max(1, workers // 10)
    schedule = frozenset((it, chunk) for it in range(iterations)  # the same chunks in both runs' iterations
                         for _, chunk in kill_schedule(it, kills, 1, FAULT_CHUNKS))
    runs = {}
    for name, planned in (("clean", frozenset()), ("killed", schedule)):
        progress(f"scale: faults, {workers} workers, {name}")
        runs[name] = _fault_run(workers, iterations, planned)
    return {"workers": workers, "chunks": FAULT_CHUNKS, "iterations": iterations, "kills_per_iteration": kills,
            "identical": runs["clean"]["parameter_hash"] == runs["killed"]["parameter_hash"], **{
                f"{name}_{key}": value for name, run in runs.items() for key, value in run.items()}}


def _fault_run(workers: int, iterations: int, schedule: frozenset) -> dict:
    from pizero_ray.bench.plans import bench_config
    from pizero_ray.bench.stub_workers import StubWorkers
    from pizero_ray.trainer.options import RunOptions

    config = bench_config(FAULT_CHUNKS * PAIRS_PER_CHUNK, PAIRS_PER_CHUNK, perturbation_rank=1)
    stubs = StubWorkers(PAIRS_PER_CHUNK, _parameters(config), chunk_delay_s(workers, FAULT_CHUNKS))
    shifted = frozenset((it + 1, chunk) for it, chunk in schedule)  # iteration 0 starts the workers: not killed
    options = RunOptions.create(iterations=iterations + 1, workers=workers, checkpoint_every=0, gradient_on="driver",
                                compile_cache="none", kill_schedule=shifted)
    result, rows = _against_stubs(config, options, stubs)
    return {"parameter_hash": result["parameter_hash"], "workers_killed": result["workers_killed"],
            "iteration_s": statistics.median(row["iteration_time_s"] for row in rows),
            "max_iteration_s": max(row["iteration_time_s"] for row in rows),
            "workers_lost": sum(row["workers_lost"] for row in rows),
            "requeued_chunks": sum(row["requeued_chunks"] for row in rows)}


# ---------------------------------------------------------------- the whole run: measure, then model

COST_PARAMETERS = (54_279, 1_000_000, 10_000_000, 100_000_000)  # the bench agent's, then 1M to 100M
PART_PAIRS = 32  # a chunk's pairs where its part is timed; the model scales the part with its chunk's pairs
MODEL_WORKERS = (8, 64, 512)
MODEL_PAIRS_PER_CHUNK = (1024, 32_768)  # a GPU worker's device call: a thousand pairs, and 32 times that
MODEL_CHUNKS_PER_WORKER = 2
GPU_RATE = 1_000_000  # agent-steps/s per GPU worker: the GPU target (docs/performance.md)
MODEL_DESIGNS = ("a_parts_on_driver", "a_parts_on_workers", "a_node_sums", "b_replayed")
SATURATION_PAIRS = (32, 1024, 32_768)


def run(progress=print, points=None) -> dict:
    """The scale model's measurements on a two-node Ray cluster on this machine, and the model built on them."""
    import contextlib
    import sys

    with contextlib.redirect_stdout(sys.stderr):  # Ray's own warnings print to stdout: the JSON alone goes there
        return _run(progress, points)


def _run(progress, points) -> dict:
    import ray
    from ray.cluster_utils import Cluster

    from pizero_ray.bench import scale_costs

    cluster = Cluster(initialize_head=True, head_node_args={
        "num_cpus": 2, "object_store_memory": 2 * 2**30, "include_dashboard": False})
    cluster.add_node(num_cpus=0, object_store_memory=2 * 2**30, resources={"scale_remote": 1})
    ray.init(address=cluster.address, logging_level="ERROR", log_to_driver=False)  # stdout is the JSON
    try:
        progress("scale: Ray's per-call costs")
        calls = scale_costs.call_costs()
        progress("scale: per-byte costs, 54k to 100M parameters")
        transfers = scale_costs.byte_costs(COST_PARAMETERS, {"scale_remote": 1})
        progress("scale: the driver's update, 54k to 100M parameters")
        updates = scale_costs.update_costs(COST_PARAMETERS, PART_PAIRS)
        rows = sweep(points if points is not None else default_points(), progress)
        fault_result = faults(progress=progress) if points is None else None
    finally:
        ray.shutdown()
        cluster.shutdown()
    measured = {"calls": calls, "transfers": transfers, "updates": updates, "ideal_compute_s": IDEAL_COMPUTE_S,
                "pairs_per_chunk": PAIRS_PER_CHUNK, "max_processes": MAX_PROCESSES}
    return {"measured": measured, "faults": fault_result, **model_rows(measured, rows)}


def unit_costs(measured: dict, rows: list[dict], design: str):
    """``scale_model.UnitCosts`` from the measurements: the driver's chunk handling from the largest sweep point
    with the parts on the driver (its CPU seconds outside the update, per chunk: with the parts on the workers
    the update's time is mostly waiting), rates from the largest transfers."""
    from pizero_ray.bench.scale_model import UnitCosts

    on_driver = [row for row in rows if row["design"] == "a_parts_on_driver"]  # one chunk a call
    largest = max(on_driver, key=lambda row: (row["chunks"], row["workers"]))
    per_chunk = (largest["driver_s"] - largest["update_s"]) / largest["chunks"]
    big = max(measured["transfers"], key=lambda row: row["bytes"])
    rank = "part_s_rank_1" if design in ("a_parts_on_driver", "b_replayed") else "part_s_rank_0"
    parts = {row["parameters"]: row[rank] for row in measured["updates"] if rank in row}
    return UnitCosts(per_chunk, big["bytes"] / big["to_other_node_s"], big["bytes"] / big["put_s"],
                     {d: s / PART_PAIRS for d, s in parts.items()},  # per pair: the model scales it by its chunk
                     {row["parameters"]: row["adam_s"] for row in measured["updates"]},
                     {row["parameters"]: row["add_part_s"] for row in measured["updates"]})


def model_rows(measured: dict, rows: list[dict]) -> dict:
    """The measured rows, then the model's: every design at ``MODEL_WORKERS`` x ``COST_PARAMETERS``."""
    from pizero_ray.bench import scale_model

    modelled, saturation = [], []
    for design in MODEL_DESIGNS:
        # Replayed updates regenerate every part on every worker: modelled at rank 1 (the default's noise), the
        # cheaper of the two.
        costs = unit_costs(measured, rows, design)
        for pairs in MODEL_PAIRS_PER_CHUNK:
            for workers in MODEL_WORKERS:
                for parameters in COST_PARAMETERS:
                    point = (workers, MODEL_CHUNKS_PER_WORKER * workers, pairs, parameters, GPU_RATE)
                    row = scale_model.iteration(costs, design, *point)
                    if design == "b_replayed":
                        row["replay_speedup_to_beat_node_sums"] = scale_model.replay_speedup_to_beat(
                            costs, "a_node_sums", *point)
                    modelled.append(row)
    costs = unit_costs(measured, rows, "a_parts_on_driver")
    for pairs in SATURATION_PAIRS:
        saturation.append({"pairs_per_chunk": pairs, "rate_per_worker": GPU_RATE,
                           "workers": scale_model.saturation_workers(costs, pairs, GPU_RATE)})
    return {"rows": rows + modelled, "driver_per_chunk_s": costs.driver_per_chunk_s, "saturation": saturation}


def table(result: dict) -> str:
    """The run in lines: unit costs, the measured points, the model at 512 workers, where the driver saturates."""
    measured = result["measured"]
    lines = [f"pizero bench --scale: a call {measured['calls']['call_in_flight_s'] * 1e3:.3f} ms in flight, "
             f"{measured['calls']['call_round_trip_s'] * 1e3:.3f} ms a round trip; the driver "
             f"{result['driver_per_chunk_s'] * 1e3:.3f} ms a chunk"]
    for row in result["rows"]:
        if row["source"] == "measured" or row["workers"] == max(MODEL_WORKERS):
            pairs = row.get("pairs_per_chunk", PAIRS_PER_CHUNK)
            lines.append(f"  {row['source']:<8} {row['design']:<19} workers {row['workers']:>4} chunks "
                         f"{row['chunks']:>5} x {pairs:>6} pairs D {row['parameters']:>11,} "
                         f"driver {row['driver_s']:9.3f} s "
                         f"iteration {row['iteration_s']:8.3f} s efficiency {row['efficiency']:.3f}")
    if result.get("faults"):
        f = result["faults"]
        lines.append(f"  faults: {f['kills_per_iteration']} of {f['workers']} workers killed in each of "
                     f"{f['iterations']} iterations: identical parameters {f['identical']}, iteration "
                     f"{f['killed_iteration_s']:.3f} s against {f['clean_iteration_s']:.3f} s without kills")
    for point in result["saturation"]:
        lines.append(f"  the driver saturates at {point['workers']:,.0f} workers with {point['pairs_per_chunk']:,} "
                     f"pairs a chunk at {point['rate_per_worker']:,} agent-steps/s each")
    return "\n".join(lines)
