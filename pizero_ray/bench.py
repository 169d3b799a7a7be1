"""`pizero bench`: how fast the population rollout, the Ray trainer and the driver are.

Measures, at the paper's agent (abstract state 64, hidden 64, k = 4, 10
simulations) on TSP10:
  - the jitted population rollout alone, in this process, chunk by chunk as a
    worker runs it: agent-steps and MCTS simulations per second (median of
    repeats after warm-up), compile time, peak memory;
  - the same work through the Ray trainer with 1 and 2 workers: iteration time,
    and its ratio to the in-process rollout (distributed efficiency);
  - the driver's update (noise regeneration + gradient + Adam) as a share of
    the iteration;
  - bytes per iteration each way;
  - a new worker's time from start to first result, cold and with the
    persistent compilation cache;
  - sweeps over the search budget and the population.
Speed targets live here, not in timed tests.
"""

from __future__ import annotations

import json
import pickle
import resource
import statistics
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pizero_ray.config import Config, build_config


@dataclass(frozen=True)
class BenchPlan:
    population: int
    chunk_size: int
    repeats: int
    trainer_iterations: int
    simulation_sweep: tuple[int, ...]
    population_sweep: tuple[int, ...]


FULL = BenchPlan(population=1000, chunk_size=40, repeats=5, trainer_iterations=6,
                 simulation_sweep=(1, 10, 50), population_sweep=(64, 256, 1000))
QUICK = BenchPlan(population=64, chunk_size=16, repeats=3, trainer_iterations=3,
                  simulation_sweep=(1, 10), population_sweep=(16, 64))


def bench_config(population: int, chunk_size: int, simulations: int = 10) -> Config:
    """The paper's agent on TSP10 (one trial per member, as the trainer's default).

    The chunk is the largest divisor of the population not above ``chunk_size``.
    """
    chunk = max(c for c in range(1, min(chunk_size, population) + 1) if population % c == 0)
    return build_config(
        "default", env="tsp", population=population, chunk_size=chunk,
        hidden_size=64, latent_size=64, memory_size=64, num_abstract_actions=4, num_simulations=simulations,
    )


def _peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def rollout(config: Config, repeats: int) -> dict:
    """The population rollout alone: every chunk of one iteration, in this process."""
    import jax
    import jax.numpy as jnp

    import envs
    from pizero_ray import rollout as rollout_lib

    env = envs.make(config.env, **config.env_kwargs())
    theta, layout = rollout_lib.flat_params(config, env)
    pairs = jnp.arange(config.chunk_size, dtype=jnp.int32)
    started = time.perf_counter()
    compiled = rollout_lib.make_pair_evaluator(config, env, layout).lower(theta, np.uint32(0), pairs).compile()
    compile_s = time.perf_counter() - started

    def one_iteration(seed: int) -> float:
        t0 = time.perf_counter()
        outputs = [compiled(theta, np.uint32(seed), pairs + start)
                   for start in range(0, config.population, config.chunk_size)]
        jax.block_until_ready(outputs)
        return time.perf_counter() - t0

    one_iteration(0)  # warm-up
    times = [one_iteration(seed) for seed in range(1, repeats + 1)]
    seconds = statistics.median(times)
    agent_steps = config.population * 2 * config.trials * env.spec.horizon
    return {
        "population": config.population,
        "simulations": config.num_simulations,
        "iteration_s": seconds,
        "agent_steps_per_s": agent_steps / seconds,
        "simulations_per_s": agent_steps * config.num_simulations / seconds,
        "compile_s": compile_s,
        "parameters": layout.size,
    }


def driver_update(config: Config, repeats: int) -> float:
    """Seconds for one update (noise regeneration + gradient + Adam) at this population."""
    import jax
    import jax.numpy as jnp

    import envs
    from pizero_ray import es
    from pizero_ray import rollout as rollout_lib

    env = envs.make(config.env)
    theta, layout = rollout_lib.flat_params(config, env)
    optimizer, update = es.make_update(config, layout.size)
    state = optimizer.init(theta)
    scores = jnp.asarray(np.random.default_rng(0).normal(size=(config.population, 2)), jnp.float32)
    valid = jnp.ones((config.population,), bool)
    jax.block_until_ready(update(theta, state, np.uint32(0), scores, valid))
    times = []
    for seed in range(repeats):
        t0 = time.perf_counter()
        jax.block_until_ready(update(theta, state, np.uint32(seed), scores, valid))
        times.append(time.perf_counter() - t0)
    return statistics.median(times)


def trainer(config: Config, workers: int, iterations: int, cache_dir: str) -> dict:
    """The Ray trainer on the same work: median iteration and update time, first-result latency."""
    from pizero_ray import driver, run_dir

    with tempfile.TemporaryDirectory(prefix="pizero-bench-") as tmp:
        path = Path(tmp)
        run_dir.write_config(path, config)
        options = driver.RunOptions(iterations=iterations, workers=workers, checkpoint_every=0,
                                    compile_cache=cache_dir)
        driver.train(path, config, options)
        rows = [row for row in run_dir.read_metrics(path) if row["iteration"] > 0]
    steady = rows[1:] or rows  # the first iteration waits for the workers' start
    first = rows[0].get("new_worker_first_result_s", [])
    return {
        "workers": workers,
        "iteration_s": statistics.median(row["iteration_time_s"] for row in steady),
        "update_s": statistics.median(row["update_time_s"] for row in steady),
        "worker_first_result_s": max(first) if first else None,
    }


def traffic(config: Config, parameters: int) -> dict:
    """Bytes per iteration: parameters once per node out, 8 bytes per pair (plus framing) back."""
    chunk_result = np.zeros((config.chunk_size, 2), np.float32)
    framed = len(pickle.dumps(chunk_result, protocol=5))
    return {
        "driver_to_workers_bytes_per_node": parameters * 4,
        "workers_to_driver_bytes": config.num_chunks * framed,
        "workers_to_driver_payload_bytes": config.population * 8,
    }


def run(plan: BenchPlan, progress=print) -> dict:
    import jax

    from pizero_ray import ray_setup

    ray_setup.init(None)  # before JAX starts its threads
    config = bench_config(plan.population, plan.chunk_size)
    progress(f"rollout: population {plan.population}, 10 simulations")
    main = rollout(config, plan.repeats)
    progress("driver update")
    update_s = driver_update(config, plan.repeats)
    sweeps = {"simulations": [], "population": []}
    for sims in plan.simulation_sweep:
        if sims == 10:
            sweeps["simulations"].append(main)
            continue
        progress(f"sweep: {sims} simulations")
        sweeps["simulations"].append(rollout(bench_config(plan.population, plan.chunk_size, sims), plan.repeats))
    for population in plan.population_sweep:
        if population == plan.population:
            sweeps["population"].append(main)
            continue
        progress(f"sweep: population {population}")
        sweeps["population"].append(rollout(bench_config(population, plan.chunk_size), plan.repeats))
    trainers = {}
    with tempfile.TemporaryDirectory(prefix="pizero-bench-cache-") as cache:
        for workers in (1, 2):
            progress(f"Ray trainer: {workers} worker(s)" + (" (cold compile cache)" if workers == 1 else ""))
            trainers[workers] = trainer(config, workers, plan.trainer_iterations, cache)
        progress("Ray trainer: a new worker with the compile cache warm")
        cached = trainer(config, 1, 2, cache)
    result = {
        "device": str(jax.devices()[0]),
        "device_kind": jax.devices()[0].device_kind,
        "population": plan.population,
        "parameters": main["parameters"],
        "rollout_agent_steps_per_s": main["agent_steps_per_s"],
        "rollout_simulations_per_s": main["simulations_per_s"],
        "rollout_iteration_s": main["iteration_s"],
        "compile_s": main["compile_s"],
        "peak_rss_mb": _peak_rss_mb(),
        "trainer_iteration_s_1_worker": trainers[1]["iteration_s"],
        "trainer_iteration_s_2_workers": trainers[2]["iteration_s"],
        "distributed_efficiency": main["iteration_s"] / trainers[2]["iteration_s"],
        "distributed_efficiency_1_worker": main["iteration_s"] / trainers[1]["iteration_s"],
        "driver_update_s": update_s,
        "driver_update_share": trainers[2]["update_s"] / trainers[2]["iteration_s"],
        "worker_first_result_s_cold": trainers[1]["worker_first_result_s"],
        "worker_first_result_s_cached": cached["worker_first_result_s"],
        **traffic(config, main["parameters"]),
        "simulation_sweep": [{k: r[k] for k in ("simulations", "agent_steps_per_s", "iteration_s")}
                             for r in sweeps["simulations"]],
        "population_sweep": [{k: r[k] for k in ("population", "agent_steps_per_s", "iteration_s")}
                             for r in sweeps["population"]],
    }
    return result


def table(result: dict) -> str:
    lines = [f"pizero bench on {result['device']} ({result['device_kind']}), TSP10, population "
             f"{result['population']} pairs, {result['parameters']} parameters"]
    for key, value in result.items():
        if key in ("simulation_sweep", "population_sweep"):
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
