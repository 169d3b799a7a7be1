"""`pizero bench`: how fast the population rollout, the Ray trainer and the driver are.

Measures, at the paper's agent (abstract state 64, hidden 64, k = 4, 10
simulations) on TSP10, in two modes: ``exact`` (full-rank Gaussian noise, the
default) and ``low_rank`` (the opt-in ``perturbation_rank`` 1, EGGROLL-style):
  - the jitted population rollout alone, in this process, chunk by chunk as a
    worker runs it, its chunks dealt over every local device (one JAX CPU
    device per core, ``local_devices``): agent-steps and MCTS simulations per
    second (median of repeats after warm-up), compile time, peak memory; and
    the same on one device;
  - a straightforward rollout for comparison: the same agent through
    ``mctx.muzero_policy`` (which samples Dirichlet noise even at weight ~0),
    batch 1 per member, full-rank noise, one device;
  - the same work through the Ray trainer with 1 and 2 workers sharing the
    same cores: iteration time, and its ratio to the in-process rollout
    (distributed efficiency);
  - the driver's update (weights, gradient parts from the workers, Adam) as a
    share of the trainer's iteration, and the update made entirely in the
    driver (regenerating every chunk's noise);
  - bytes per iteration each way;
  - a new worker's time from start to first result, cold and with the
    persistent compilation cache;
  - sweeps over the search budget and the population.
Speed targets live here, not in timed tests.
"""

from __future__ import annotations

import json
import pickle
import statistics
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pizero_ray.config import Config, build_config, largest_divisor_at_most

LOW_RANK = 1  # the perturbation rank the benchmark's low-rank mode uses


@dataclass(frozen=True)
class BenchPlan:
    population: int
    chunk_size: int  # exact mode: larger chunks were no faster (docs/performance.md)
    low_rank_chunk_size: int  # low-rank mode: bigger chunks make bigger shared matrix products
    repeats: int
    trainer_iterations: int
    simulation_sweep: tuple[int, ...]
    population_sweep: tuple[int, ...]
    sweep_modes: tuple[str, ...]  # which modes the sweeps cover
    planner_sweep: tuple[str, ...]  # exact mode, population as above
    straightforward: bool  # also measure the straightforward rollout (and the speed-ups over it)
    one_device: bool  # with several local devices, also measure each mode on one of them
    exact_trainer_workers: tuple[int, ...]  # the first run starts with a cold compile cache; 2 must be among them
    low_rank_trainer_workers: tuple[int, ...]


FULL = BenchPlan(population=1000, chunk_size=40, low_rank_chunk_size=250, repeats=7, trainer_iterations=10,
                 simulation_sweep=(1, 10, 50), population_sweep=(64, 256, 1000), sweep_modes=("exact", "low_rank"),
                 planner_sweep=("muzero", "gumbel", "none"), straightforward=True, one_device=True,
                 exact_trainer_workers=(1, 2), low_rank_trainer_workers=(1, 2))
QUICK = BenchPlan(population=64, chunk_size=16, low_rank_chunk_size=32, repeats=3, trainer_iterations=3,
                  simulation_sweep=(10,), population_sweep=(64,), sweep_modes=("exact",),
                  planner_sweep=(), straightforward=False, one_device=False, exact_trainer_workers=(2,),
                  low_rank_trainer_workers=())


def bench_config(population: int, chunk_size: int, simulations: int = 10, perturbation_rank: int = 0,
                 root_noise: float = 0.0, planner: str = "muzero", devices: int = 1) -> Config:
    """The paper's agent on TSP10 (one trial per member, as the trainer's default).

    The chunk is the largest divisor of the population not above ``chunk_size``
    that still gives each of ``devices`` devices a chunk.
    """
    chunk = largest_divisor_at_most(population, max(1, min(chunk_size, population // devices)))
    return build_config(
        "default", env="tsp", population=population, chunk_size=chunk, perturbation_rank=perturbation_rank,
        hidden_size=64, latent_size=64, memory_size=64, num_abstract_actions=4, num_simulations=simulations,
        root_noise=root_noise, planner=planner,
    )


@dataclass(frozen=True)
class CompiledRollout:
    config: Config
    one_iteration: object  # (seed) -> seconds for every chunk of one iteration
    compile_s: float
    parameters: int
    agent_steps: int  # per iteration
    devices: int  # local devices the chunks were dealt over


def compile_rollout(config: Config, max_devices: int | None = None) -> CompiledRollout:
    """The population rollout as a worker runs it, compiled for this process's devices (or the first few)."""
    import envs
    from pizero_ray.es import population
    from pizero_ray.trainer import local_devices

    theta, _ = population.flat_params(config, envs.make(config.env, **config.env_kwargs()))
    theta = np.asarray(theta)
    started = time.perf_counter()
    chunks = local_devices.ChunkScorer(config, max_devices)
    chunks.wait_until_compiled()
    compile_s = time.perf_counter() - started  # every device's program
    first_pairs = range(0, config.population, config.chunk_size)

    def one_iteration(seed: int) -> float:
        t0 = time.perf_counter()
        chunks.score_all(theta, seed, first_pairs)  # returns once every chunk's scores are on the host
        return time.perf_counter() - t0

    one_iteration(0)  # warm-up
    agent_steps = config.population * chunks.agent_steps_per_pair
    return CompiledRollout(config, one_iteration, compile_s, chunks.parameters, agent_steps, chunks.num_devices)


def rollouts(configs: dict[str, Config], repeats: int, max_devices: dict[str, int] | None = None) -> dict[str, dict]:
    """The population rollout alone, in this process: median iteration of each config.

    Chunks are dealt over all local devices unless ``max_devices`` limits a
    config. Repeats of the configs are interleaved, so that a slow spell of a
    shared machine hits all of them alike and their ratios stay meaningful.
    """
    limits = max_devices or {}
    compiled = {name: compile_rollout(config, limits.get(name)) for name, config in configs.items()}
    times: dict[str, list[float]] = {name: [] for name in configs}
    for seed in range(1, repeats + 1):
        for name, run in compiled.items():
            times[name].append(run.one_iteration(seed))
    results = {}
    for name, run in compiled.items():
        seconds = statistics.median(times[name])
        results[name] = {
            "population": run.config.population,
            "simulations": run.config.num_simulations,
            "devices": run.devices,
            "iteration_s": seconds,
            "agent_steps_per_s": run.agent_steps / seconds,
            "simulations_per_s": run.agent_steps * run.config.num_simulations / seconds,
            "compile_s": run.compile_s,
            "parameters": run.parameters,
        }
    return results


def rollout(config: Config, repeats: int) -> dict:
    """The population rollout of one config alone (see ``rollouts``)."""
    return rollouts({"rollout": config}, repeats)["rollout"]


def planner_sweep(plan: BenchPlan, progress=print, devices: int = 1) -> list[dict]:
    """The exact-mode rollout with each planner (mctx MuZero, mctx Gumbel MuZero, none), interleaved."""
    progress(f"planner sweep (exact, interleaved): {', '.join(plan.planner_sweep)}")
    configs = {planner: bench_config(plan.population, plan.chunk_size, planner=planner, devices=devices)
               for planner in plan.planner_sweep}
    return [{"planner": planner, "agent_steps_per_s": r["agent_steps_per_s"], "iteration_s": r["iteration_s"]}
            for planner, r in rollouts(configs, plan.repeats).items()]


def driver_update(config: Config, repeats: int) -> float:
    """Seconds for one update made entirely in the driver (every chunk's noise regenerated, gradient, Adam).

    That is the driver's fallback; in the trainer the workers return the parts
    from the noise they kept (``trainer_update_s``).
    """
    import jax

    import envs
    from pizero_ray import es
    from pizero_ray.es import population

    env = envs.make(config.env)
    theta, layout = population.flat_params(config, env)
    strategy = es.make_strategy(config, layout.perturbation)
    state = strategy.init(theta)
    scores = np.random.default_rng(0).normal(size=(config.population, 2)).astype(np.float32)
    valid = np.ones((config.population,), bool)

    def update(seed: int):
        weights = strategy.weights(scores, valid)
        parts = [strategy.parts.chunk_here(seed, weights, index) for index in range(config.num_chunks)]
        return strategy.tell(state, scores, valid, parts)[0]

    jax.block_until_ready(update(0))
    times = []
    for seed in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(update(seed))
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def trainer(config: Config, workers: int, iterations: int, cache_dir: str, cpus_per_worker: int = 1,
            gpus_per_worker: float = 0.0) -> dict:
    """The Ray trainer on the same work: median iteration and update time, first-result latency."""
    from pizero_ray.storage import run_dir
    from pizero_ray.trainer import driver

    with tempfile.TemporaryDirectory(prefix="pizero-bench-") as tmp:
        path = Path(tmp)
        run_dir.write_config(path, config)
        options = driver.RunOptions.create(iterations=iterations, workers=workers, cpus_per_worker=cpus_per_worker,
                                           gpus_per_worker=gpus_per_worker, checkpoint_every=0, compile_cache=cache_dir)
        driver.train(path, config, options)
        rows = [row for row in run_dir.read_metrics(path) if row["iteration"] > 0]
    # The first iterations wait for the workers' start and, on a worker with
    # several devices, for its other devices' compiles: the last half is steady.
    steady = rows[len(rows) // 2:]
    first = rows[0].get("new_worker_first_result_s", [])
    return {
        "workers": workers,
        "iteration_s": statistics.median(row["iteration_time_s"] for row in steady),
        "update_s": statistics.median(row["update_time_s"] for row in steady),
        "worker_first_result_s": max(first) if first else None,
    }


def worker_memory(config: Config, cache_dir: str) -> float:
    """Peak resident memory (MB) of one Ray worker actor after evaluating a whole iteration."""
    import ray

    import envs
    from pizero_ray import es
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


def traffic(config: Config, parameters: int) -> dict:
    """Bytes per iteration, each way.

    Out: the parameters once per node, then each chunk's weights (4 bytes per
    pair). Back: each chunk's scores (8 bytes per pair) and its share of the
    gradient (one parameter vector per chunk). Framing is pickle's, as Ray's.
    """
    def framed(shape) -> int:
        return len(pickle.dumps(np.zeros(shape, np.float32), protocol=5))

    chunks = config.num_chunks
    return {
        "driver_to_workers_bytes_per_node": parameters * 4,
        "driver_to_workers_weights_bytes": chunks * framed((config.chunk_size,)),
        "workers_to_driver_bytes": chunks * (framed((config.chunk_size, 2)) + framed((parameters,))),
        "workers_to_driver_payload_bytes": config.population * 8 + chunks * parameters * 4,
    }


def _rollouts_and_sweeps(plan: BenchPlan, configs: dict, modes: dict, devices: int, progress) -> tuple:
    """The in-process rollouts (main, one-device, straightforward), driver updates, and the sweeps."""
    measured, one_device = dict(configs), {}
    if devices > 1 and plan.one_device:  # how much of the speed is the devices': each mode again on one device
        one_device = {f"{mode}_one_device": 1 for mode in modes}
        measured.update({f"{mode}_one_device": configs[mode] for mode in modes})
    if plan.straightforward:
        # A Dirichlet weight of 1e-9 routes the search through mctx.muzero_policy,
        # noise sampling included: the rollout as it is first written, on one device.
        measured["straightforward"] = bench_config(plan.population, plan.chunk_size, root_noise=1e-9)
        one_device["straightforward"] = 1
    progress(f"rollouts ({', '.join(measured)}; interleaved): population {plan.population}, 10 simulations, "
             f"{devices} device(s)")
    main = rollouts(measured, plan.repeats, one_device)
    update_s, sweeps = {}, {"simulations": [], "population": []}
    for mode, (rank, chunk) in modes.items():
        progress(f"driver update, regenerating every chunk ({mode})")
        update_s[mode] = driver_update(configs[mode], plan.repeats)
        if mode not in plan.sweep_modes:
            continue
        sweep_configs = {
            "simulations": {sims: bench_config(plan.population, chunk, sims, perturbation_rank=rank, devices=devices)
                            for sims in plan.simulation_sweep},
            "population": {population: bench_config(population, chunk, perturbation_rank=rank, devices=devices)
                           for population in plan.population_sweep},
        }
        for kind, points in sweep_configs.items():
            for value, config in points.items():
                if config == configs[mode]:  # the main measurement's point: not measured twice
                    result = main[mode]
                else:
                    progress(f"sweep ({mode}): {kind} {value}")
                    result = rollout(config, plan.repeats)
                sweeps[kind].append({"mode": mode, **result})
    return main, update_s, sweeps


def _ray_trainers(plan: BenchPlan, configs: dict, modes: dict, share, progress) -> tuple:
    """The Ray trainer with 1 and 2 workers per mode, a worker joining with a warm cache, a worker's memory.

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
        worker_rss = {mode: worker_memory(configs[mode], cache) for mode in modes
                      if mode == "exact" or plan.low_rank_trainer_workers}
    return trainers, cached, worker_rss


def _mode_figures(mode: str, main: dict, update_s: dict, trainers: dict, share, straightforward) -> dict:
    """One mode's figures: rollout speed, compile, driver update, speed-ups, the Ray trainer's efficiency."""
    suffix = "" if mode == "exact" else "_low_rank"
    result = {
        f"rollout_agent_steps_per_s{suffix}": main[mode]["agent_steps_per_s"],
        f"rollout_simulations_per_s{suffix}": main[mode]["simulations_per_s"],
        f"rollout_iteration_s{suffix}": main[mode]["iteration_s"],
        f"compile_s{suffix}": main[mode]["compile_s"],
        f"driver_update_regenerating_s{suffix}": update_s[mode],
    }
    if f"{mode}_one_device" in main:
        result[f"rollout_agent_steps_per_s{suffix}_one_device"] = main[f"{mode}_one_device"]["agent_steps_per_s"]
    if straightforward:
        for variant in (mode, f"{mode}_one_device"):
            if variant in main:
                result[f"speedup_vs_straightforward{suffix}{variant[len(mode):]}"] = (
                    main[variant]["agent_steps_per_s"] / straightforward["agent_steps_per_s"])
    for workers in (1, 2):  # the Ray trainer's figures, where this plan ran them
        if (mode, workers) not in trainers:
            continue
        run = trainers[mode, workers]
        label = "1_worker" if workers == 1 else "2_workers"
        result[f"trainer_cpus_per_worker_{label}"] = share(workers)[0]
        result[f"trainer_iteration_s_{label}{suffix}"] = run["iteration_s"]
        efficiency = main[mode]["iteration_s"] / run["iteration_s"]
        if workers == 2:
            result[f"distributed_efficiency{suffix}"] = efficiency
            result[f"trainer_update_s{suffix}"] = run["update_s"]
            result[f"driver_update_share{suffix}"] = run["update_s"] / run["iteration_s"]
        else:
            result[f"distributed_efficiency_1_worker{suffix}"] = efficiency
    return result


def run(plan: BenchPlan, progress=print, worker_gpus: float = 0.0) -> dict:
    """Every measurement of ``plan``; the Ray trainer's W workers share ``worker_gpus`` GPUs (0: CPU workers)."""
    import jax

    from pizero_ray.trainer import local_devices, ray_setup

    ray_setup.init(None)  # before JAX starts its threads
    devices = len(jax.local_devices())
    modes = {"exact": (0, plan.chunk_size), "low_rank": (LOW_RANK, plan.low_rank_chunk_size)}
    configs = {mode: bench_config(plan.population, chunk, perturbation_rank=rank, devices=devices)
               for mode, (rank, chunk) in modes.items()}
    main, update_s, sweeps = _rollouts_and_sweeps(plan, configs, modes, devices, progress)
    straightforward = main.pop("straightforward", None)
    planners = planner_sweep(plan, progress, devices) if plan.planner_sweep else []

    def share(workers: int) -> tuple[int, float]:
        # The workers share the cores the in-process rollout used, and the GPUs (fractions of one, if need be).
        return max(1, devices // workers), worker_gpus / workers

    trainers, cached, worker_rss = _ray_trainers(plan, configs, modes, share, progress)
    result = {
        "device": str(jax.devices()[0]),
        "device_kind": jax.devices()[0].device_kind,
        "rollout_devices": devices,
        "trainer_worker_gpus": worker_gpus,
        "population": plan.population,
        "parameters": main["exact"]["parameters"],
        "low_rank_perturbation_rank": LOW_RANK,
        "low_rank_chunk_size": configs["low_rank"].chunk_size,
    }
    if straightforward:
        result["straightforward_agent_steps_per_s"] = straightforward["agent_steps_per_s"]
    for mode in modes:
        result.update(_mode_figures(mode, main, update_s, trainers, share, straightforward))
    result.update({
        "peak_rss_mb": local_devices.peak_rss_mb(),
        "worker_peak_rss_mb": worker_rss["exact"],
        **({"worker_peak_rss_mb_low_rank": worker_rss["low_rank"]} if "low_rank" in worker_rss else {}),
        "worker_first_result_s_cold": trainers["exact", plan.exact_trainer_workers[0]]["worker_first_result_s"],
        "worker_first_result_s_cached": cached["worker_first_result_s"],
        **traffic(configs["exact"], main["exact"]["parameters"]),
        "simulation_sweep": [{k: r[k] for k in ("mode", "simulations", "agent_steps_per_s", "iteration_s")}
                             for r in sweeps["simulations"]],
        "population_sweep": [{k: r[k] for k in ("mode", "population", "agent_steps_per_s", "iteration_s")}
                             for r in sweeps["population"]],
        "planner_sweep": planners,
    })
    return result


def table(result: dict) -> str:
    lines = [f"pizero bench on {result['device']} ({result['device_kind']}), TSP10, population "
             f"{result['population']} pairs, {result['parameters']} parameters"]
    for key, value in result.items():
        if key.endswith("_sweep"):
            for row in value:
                label = ", ".join(f"{k} {v:,.3f}" if isinstance(v, float) else f"{k} {v}" for k, v in row.items())
                lines.append(f"  {key}: {label}")
        elif isinstance(value, float):
            lines.append(f"  {key:<36} {value:,.3f}")
        else:
            lines.append(f"  {key:<36} {value}")
    return "\n".join(lines)


def to_json(result: dict) -> str:
    return json.dumps(result)
