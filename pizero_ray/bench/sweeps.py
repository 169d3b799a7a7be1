"""The project's rollout across search budgets, populations and planners (each sweep's points interleaved)."""

from __future__ import annotations

from pizero_ray.bench.plans import BenchPlan, bench_config
from pizero_ray.bench.rollout import rollout, rollouts
from pizero_ray.config import Config


def budget_and_population_sweeps(plan: BenchPlan, mode: str, rank: int, chunk: int, devices: int,
                                 main_config: Config, main_result: dict, progress) -> dict[str, list[dict]]:
    """One mode's rollout at each search budget and population of ``plan``: {"simulations": [...], "population": [...]}.

    The mode's main measurement (``main_config``, ``main_result``) stands for its own point.
    """
    points = {
        "simulations": {sims: bench_config(plan.population, chunk, sims, perturbation_rank=rank, devices=devices)
                        for sims in plan.simulation_sweep},
        "population": {population: bench_config(population, chunk, perturbation_rank=rank, devices=devices)
                       for population in plan.population_sweep},
    }
    sweeps: dict[str, list[dict]] = {}
    for kind, configs in points.items():
        sweeps[kind] = []
        for value, config in configs.items():
            if config == main_config:  # the main measurement's point: not measured twice
                result = main_result
            else:
                progress(f"sweep ({mode}): {kind} {value}")
                result = rollout(config, plan.repeats)
            sweeps[kind].append({"mode": mode, **result})
    return sweeps


def planner_sweep(plan: BenchPlan, progress=print, devices: int = 1) -> list[dict]:
    """The exact-mode rollout with each planner (mctx MuZero, mctx Gumbel MuZero, none), interleaved."""
    progress(f"planner sweep (exact, interleaved): {', '.join(plan.planner_sweep)}")
    configs: dict[str, Config] = {planner: bench_config(plan.population, plan.chunk_size, planner=planner,
                                                        devices=devices) for planner in plan.planner_sweep}
    return [{"planner": planner, "agent_steps_per_s": r["agent_steps_per_s"], "iteration_s": r["iteration_s"]}
            for planner, r in rollouts(configs, plan.repeats).items()]
