#!/usr/bin/env python3
"""Issue 46's GPU levers timed on this machine's CPU, interleaved: what each costs where there is no GPU.

1. The rollout with each --episode-loop and --simulation-loop (the bench agent on TSP10, one device, rank-1
   and exact noise, population 64 in chunks of 32): agent-steps/s, compile time and the while-loop nest.
2. A chunk's low-rank gradient part with a loop per matrix (the driver's) and with every matrix in one loop
   (GPU workers', ``GradientParts.many``), chunks of 32 and 256 pairs: median milliseconds, and whether the
   bits agree.

Prints one JSON object. Run it with nothing else on the machine: ``python scripts/cpu_levers.py``.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import statistics
import time

import jax
import jax.numpy as jnp
import numpy as np


def loop_settings(repeats: int = 5) -> list[dict]:
    from pizero_ray.bench.plans import bench_config
    from pizero_ray.bench.rollout import pair_scorer_loops, rollouts

    configs = {}
    for rank in (1, 0):
        base = bench_config(64, 32, perturbation_rank=rank)
        for episode_loop in ("until_done", "horizon"):
            for simulation_loop in ("fori", "unrolled"):
                configs[(rank, episode_loop, simulation_loop)] = dataclasses.replace(
                    base, episode_loop=episode_loop, simulation_loop=simulation_loop)
    timed = rollouts({str(key): config for key, config in configs.items()}, repeats,
                     max_devices={str(key): 1 for key in configs})
    return [{"perturbation_rank": key[0], "episode_loop": key[1], "simulation_loop": key[2],
             "agent_steps_per_s": round(timed[str(key)]["agent_steps_per_s"]),
             "compile_s": round(timed[str(key)]["compile_s"], 1),
             "loop_shape": pair_scorer_loops(config)["data_dependent_loop_shape"]}
            for key, config in configs.items()]


def part_loops(repeats: int = 30) -> list[dict]:
    import envs
    from pizero_ray import es
    from pizero_ray.bench.plans import bench_config
    from pizero_ray.es import population

    rows = []
    for chunk in (32, 256):
        config = bench_config(1024, chunk, perturbation_rank=1)
        perturbation = population.flat_params(config, envs.make("tsp"))[1].perturbation
        noise = jax.random.normal(jax.random.PRNGKey(0), (chunk, perturbation.noise_size))
        weights = jnp.linspace(-1, 1, chunk)
        forms = {one_loop: jax.jit(functools.partial(es.weighted_noise_sum, perturbation=perturbation,
                                                     one_loop=one_loop))
                 for one_loop in (False, True)}
        parts = {one_loop: np.asarray(form(weights, noise)) for one_loop, form in forms.items()}
        times: dict[bool, list[float]] = {one_loop: [] for one_loop in forms}
        for _ in range(repeats):
            for one_loop, form in forms.items():
                started = time.perf_counter()
                form(weights, noise).block_until_ready()
                times[one_loop].append(time.perf_counter() - started)
        rows.append({"chunk_pairs": chunk, "loop_per_matrix_ms": round(1e3 * statistics.median(times[False]), 3),
                     "one_loop_ms": round(1e3 * statistics.median(times[True]), 3),
                     "same_bits": bool(np.array_equal(parts[False], parts[True]))})
    return rows


def main() -> None:
    import os

    print(json.dumps({"cpu_cores": len(os.sched_getaffinity(0)), "jax": jax.__version__,
                      "loop_settings": loop_settings(), "gradient_part_loops": part_loops()}, indent=1))


if __name__ == "__main__":
    main()
