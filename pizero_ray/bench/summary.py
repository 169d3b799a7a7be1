"""The bench's measurements as its one JSON object (the keys docs/ and scripts/device_check.py read), or a table."""

from __future__ import annotations

import json
from dataclasses import dataclass, field

from pizero_ray.bench.plans import LOW_RANK

MODES = ("exact", "low_rank")
# The rollouts the modes' speed-ups are measured against: the plain one (``straightforward``), and the project's
# own rollout on one device with mctx.muzero_policy's Dirichlet draw (what the bench once called straightforward).
BASELINES = ("straightforward", "one_device_with_dirichlet_draw")


@dataclass(frozen=True)
class Measurements:
    """What one bench run measured, before it is named and divided into the reported figures."""

    device: str
    device_kind: str
    devices: int  # local devices the in-process rollout dealt its chunks over
    worker_gpus: float  # GPUs the Ray trainer's workers shared
    population: int
    low_rank_chunk_size: int
    rollouts: dict[str, dict]  # timing.figures of each mode, "<mode>_one_device" and each baseline measured
    driver_update_s: dict[str, float]  # per mode: the update made entirely in the driver
    sweeps: dict[str, list[dict]]  # "simulations", "population": rows of timing.figures with their mode
    planners: list[dict]
    trainers: dict[tuple[str, int], dict]  # (mode, workers) -> trainer.trainer's figures
    cold_trainer: dict  # the first trainer run, its compile cache cold
    cached_trainer: dict  # a new worker with the compile cache warm
    cpus_per_worker: dict[int, int]  # workers -> the CPUs each got
    worker_peak_rss_mb: dict[str, float]  # per mode where measured
    peak_rss_mb: float  # this process's
    program_loops: dict[str, dict] = field(default_factory=dict)  # per mode: rollout.pair_scorer_loops


def result(m: Measurements) -> dict:
    """The bench's JSON object."""
    exact = m.rollouts["exact"]
    out = {
        "device": m.device, "device_kind": m.device_kind, "rollout_devices": m.devices,
        "trainer_worker_gpus": m.worker_gpus, "population": m.population, "parameters": exact["parameters"],
        "low_rank_perturbation_rank": LOW_RANK, "low_rank_chunk_size": m.low_rank_chunk_size,
        **{f"{baseline}_agent_steps_per_s": m.rollouts[baseline]["agent_steps_per_s"]
           for baseline in BASELINES if baseline in m.rollouts},
    }
    for mode in MODES:
        out.update(_mode_figures(m, mode))
    out.update({
        "peak_rss_mb": m.peak_rss_mb,
        **{f"worker_peak_rss_mb{_suffix(mode)}": rss for mode, rss in m.worker_peak_rss_mb.items()},
        "worker_first_result_s_cold": m.cold_trainer["worker_first_result_s"],
        "worker_first_result_s_cached": m.cached_trainer["worker_first_result_s"],
        "simulation_sweep": [{k: r[k] for k in ("mode", "simulations", "agent_steps_per_s", "iteration_s")}
                             for r in m.sweeps["simulations"]],
        "population_sweep": [{k: r[k] for k in ("mode", "population", "agent_steps_per_s", "iteration_s")}
                             for r in m.sweeps["population"]],
        "planner_sweep": m.planners,
        "program_loops": m.program_loops,
    })
    return out


def _suffix(mode: str) -> str:
    return "" if mode == "exact" else f"_{mode}"


def _mode_figures(m: Measurements, mode: str) -> dict:
    """One mode's figures: rollout speed, compile, driver update, speed-ups, the Ray trainer's."""
    suffix, main = _suffix(mode), m.rollouts[mode]
    one_device = m.rollouts.get(f"{mode}_one_device")
    figures = {
        f"rollout_agent_steps_per_s{suffix}": main["agent_steps_per_s"],
        f"rollout_simulations_per_s{suffix}": main["simulations_per_s"],
        f"rollout_iteration_s{suffix}": main["iteration_s"],
        f"compile_s{suffix}": main["compile_s"],
        f"driver_update_regenerating_s{suffix}": m.driver_update_s[mode],
    }
    if one_device:
        figures[f"rollout_agent_steps_per_s{suffix}_one_device"] = one_device["agent_steps_per_s"]
    for baseline in BASELINES:
        if baseline not in m.rollouts:
            continue
        for variant, measured in (("", main), ("_one_device", one_device)):
            if measured:
                figures[f"speedup_vs_{baseline}{suffix}{variant}"] = (
                    measured["agent_steps_per_s"] / m.rollouts[baseline]["agent_steps_per_s"])
    return {**figures, **_trainer_figures(m, mode, suffix)}


def _trainer_figures(m: Measurements, mode: str, suffix: str) -> dict:
    """The Ray trainer's figures of one mode, where the plan ran them; its traffic from the 2-worker run."""
    figures = {}
    for workers, label in ((1, "1_worker"), (2, "2_workers")):
        run = m.trainers.get((mode, workers))
        if run is None:
            continue
        figures[f"trainer_cpus_per_worker_{label}"] = m.cpus_per_worker[workers]
        figures[f"trainer_iteration_s_{label}{suffix}"] = run["iteration_s"]
        efficiency = m.rollouts[mode]["iteration_s"] / run["iteration_s"]
        if workers == 1:
            figures[f"distributed_efficiency_1_worker{suffix}"] = efficiency
            continue
        figures.update({
            f"distributed_efficiency{suffix}": efficiency,
            f"trainer_update_s{suffix}": run["update_s"],
            f"driver_update_share{suffix}": run["update_s"] / run["iteration_s"],
            # Counted by the pool, object by object (bench.traffic); where the gradient parts were formed
            # decides whether they are in it.
            f"trainer_gradient_on{suffix}": run["gradient_on"],
            f"trainer_bytes_to_workers{suffix}": run["bytes_to_workers"],
            f"trainer_bytes_from_workers{suffix}": run["bytes_from_workers"],
        })
    return figures


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
