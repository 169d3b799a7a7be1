"""One bench run: every measurement of a plan, in the order that keeps them fair, then the report."""

from __future__ import annotations

import dataclasses
import functools
import tempfile

from pizero_ray.bench import summary
from pizero_ray.bench.plans import LOW_RANK, BenchPlan, bench_config
from pizero_ray.bench.rollout import compile_rollout, pair_scorer_loops
from pizero_ray.bench.straightforward import compile_straightforward
from pizero_ray.bench.sweeps import budget_and_population_sweeps, planner_sweep
from pizero_ray.bench.timing import time_interleaved
from pizero_ray.bench.training_runs import trainer, worker_memory
from pizero_ray.bench.update import driver_update


def run(plan: BenchPlan, progress=print, worker_gpus: float = 0.0) -> dict:
    """Every measurement of ``plan``; the Ray trainer's W workers share ``worker_gpus`` GPUs (0: CPU workers)."""
    import jax

    from pizero_ray.trainer import chunk_scoring, ray_setup

    ray_setup.init(None)  # before JAX starts its threads
    devices = len(jax.local_devices())
    modes = {"exact": (0, plan.chunk_size), "low_rank": (LOW_RANK, plan.low_rank_chunk_size)}
    configs = {mode: bench_config(plan.population, chunk, perturbation_rank=rank, devices=devices)
               for mode, (rank, chunk) in modes.items()}
    rollouts = _main_rollouts(plan, configs, devices, progress)
    progress("the rollout programs' while loops")
    program_loops = {mode: pair_scorer_loops(config) for mode, config in configs.items()}
    program_loops["low_rank_planner_none"] = pair_scorer_loops(dataclasses.replace(configs["low_rank"], planner="none"))
    update_s = {}
    for mode in modes:
        progress(f"driver update, regenerating every chunk ({mode})")
        update_s[mode] = driver_update(configs[mode], plan.repeats)
    sweeps: dict[str, list[dict]] = {"simulations": [], "population": []}
    for mode in plan.sweep_modes:
        rank, chunk = modes[mode]
        found = budget_and_population_sweeps(plan, mode, rank, chunk, devices, configs[mode], rollouts[mode], progress)
        for kind in sweeps:
            sweeps[kind] += found[kind]
    planners = planner_sweep(plan, progress, devices) if plan.planner_sweep else []
    # The workers share the cores the in-process rollout used, and the GPUs (fractions of one, if need be).
    share = functools.partial(_worker_share, devices, worker_gpus)
    trainers, cached, worker_rss = _ray_trainers(plan, configs, share, progress)
    return summary.result(summary.Measurements(
        device=str(jax.devices()[0]), device_kind=jax.devices()[0].device_kind, devices=devices,
        worker_gpus=worker_gpus, population=plan.population, low_rank_chunk_size=configs["low_rank"].chunk_size,
        rollouts=rollouts, driver_update_s=update_s, sweeps=sweeps, planners=planners, trainers=trainers,
        cold_trainer=trainers["exact", plan.exact_trainer_workers[0]], cached_trainer=cached,
        cpus_per_worker={workers: share(workers)[0] for _, workers in trainers}, worker_peak_rss_mb=worker_rss,
        peak_rss_mb=chunk_scoring.peak_rss_mb(), program_loops=program_loops))


def _worker_share(devices: int, worker_gpus: float, workers: int) -> tuple[int, float]:
    """(CPUs, GPUs) per worker when ``workers`` workers share this process's devices and ``worker_gpus`` GPUs."""
    return max(1, devices // workers), worker_gpus / workers


def _main_rollouts(plan: BenchPlan, configs: dict, devices: int, progress) -> dict[str, dict]:
    """Each mode's rollout over every device, and what the plan compares them with, all timed interleaved."""
    to_compile = {mode: functools.partial(compile_rollout, config) for mode, config in configs.items()}
    if devices > 1 and plan.one_device:  # how much of the speed is the devices': each mode again on one device
        to_compile.update({f"{mode}_one_device": functools.partial(compile_rollout, config, 1)
                           for mode, config in configs.items()})
    if plan.one_device_with_dirichlet_draw:
        # A Dirichlet weight of 1e-9 routes the project's search through mctx.muzero_policy, which draws the noise
        # it then all but ignores; everything else is the project's rollout, on one device.
        drawn = bench_config(plan.population, plan.chunk_size, root_noise=1e-9)
        to_compile["one_device_with_dirichlet_draw"] = functools.partial(compile_rollout, drawn, 1)
    if plan.straightforward:  # the plain vmap of mctx.muzero_policy per member (bench.straightforward)
        to_compile["straightforward"] = functools.partial(compile_straightforward, configs["exact"])
    progress(f"rollouts ({', '.join(to_compile)}; interleaved): population {plan.population}, 10 simulations, "
             f"{devices} device(s)")
    return time_interleaved({name: compile_now() for name, compile_now in to_compile.items()}, plan.repeats)


def _ray_trainers(plan: BenchPlan, configs: dict, share, progress) -> tuple:
    """The Ray trainer with the plan's worker counts per mode, a worker joining with a warm cache, a worker's memory.

    ``share(workers) -> (cpus, gpus)`` per worker.
    """
    trainers = {}
    with tempfile.TemporaryDirectory(prefix="pizero-bench-cache-") as cache:
        for mode, counts in (("exact", plan.exact_trainer_workers), ("low_rank", plan.low_rank_trainer_workers)):
            for workers in counts:
                cold = " (cold compile cache)" if not trainers else ""
                cpus, gpus = share(workers)
                progress(f"Ray trainer ({mode}): {workers} worker(s), {cpus} CPU(s) and {gpus:g} GPU each{cold}")
                trainers[mode, workers] = trainer(configs[mode], workers, plan.trainer_iterations, cache, cpus, gpus)
            if mode == "exact":
                progress("Ray trainer (exact): a new 1-CPU worker with the compile cache warm")
                cached = trainer(configs["exact"], 1, 2, cache, gpus_per_worker=share(1)[1])
        progress("peak memory of a worker")
        worker_rss = {mode: worker_memory(configs[mode], cache) for mode in configs
                      if mode == "exact" or plan.low_rank_trainer_workers}
    return trainers, cached, worker_rss

