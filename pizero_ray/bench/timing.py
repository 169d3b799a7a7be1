"""Timing compiled rollouts against each other: repeats interleaved, medians, and the figures made of them."""

from __future__ import annotations

import statistics
from dataclasses import dataclass
from typing import Callable

from pizero_ray.config import Config


@dataclass(frozen=True)
class CompiledRollout:
    """A population rollout compiled and warmed up, ready to be timed, whichever way it is built."""

    config: Config
    one_iteration: Callable[[int], float]  # (seed) -> seconds to score the whole population once
    compile_s: float
    parameters: int
    agent_steps: int  # environment steps one iteration plays, over every member's episodes
    devices: int  # local devices the iteration runs on


def time_interleaved(compiled: dict[str, CompiledRollout], repeats: int) -> dict[str, dict]:
    """The median iteration of each rollout and the rates made of it, keyed as ``compiled``.

    The rollouts take turns, repeat by repeat, so that a slow spell of a shared
    machine hits all of them alike and their ratios stay meaningful.
    """
    times: dict[str, list[float]] = {name: [] for name in compiled}
    for seed in range(1, repeats + 1):  # seed 0 was the warm-up
        for name, run in compiled.items():
            times[name].append(run.one_iteration(seed))
    return {name: figures(run, statistics.median(times[name])) for name, run in compiled.items()}


def figures(run: CompiledRollout, iteration_s: float) -> dict:
    """What the bench reports of one timed rollout."""
    return {
        "population": run.config.population,
        "planner": run.config.planner,
        "simulations": run.config.num_simulations,
        "chunk_size": run.config.chunk_size,
        "chunks_per_launch": run.config.chunks_per_launch,
        "devices": run.devices,
        "iteration_s": iteration_s,
        "agent_steps_per_s": run.agent_steps / iteration_s,
        "simulations_per_s": run.agent_steps * run.config.num_simulations / iteration_s,
        "compile_s": run.compile_s,
        "parameters": run.parameters,
    }
