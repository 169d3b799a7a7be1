"""The population rollout on one device, point by point, as a GPU worker plays a whole population.

Each point is timed alone, one after another (not interleaved as ``timing.time_interleaved`` does): the points
differ in size by orders of magnitude, and a small one timed between large ones would measure their wake. A
point builds one ``chunk_scoring.ChunkScorer`` on one device and hands it the whole population's consecutive
chunks in one ``score_many`` call, as a GPU worker given ``--chunks-per-call`` = all its chunks is, and (unless
the point's overrides set ``chunks_per_launch``) as one launch: one device call of every pair. A warm-up call
first, then the median of ``repeats`` calls. A point that fails (out of device memory, a bad setting) records
its error in one line and the sweep goes on.

``device_memory_bytes`` is the device's ``peak_bytes_in_use`` after the point (GPUs; the CPU reports none). The
peak is the process's since it started, not the point's: read in a sweep of growing populations, each point's
figure is its own peak or an earlier, larger point's.

Run as a module, it sweeps the points of a JSON file and appends each row to a JSON-lines file as soon as it
is measured (scripts/device_run.py runs it in a subprocess per set of XLA flags, and keeps the rows of a
sweep cut off at its deadline).
"""

from __future__ import annotations

import argparse
import dataclasses
import gc
import json
import statistics
import sys
import time
from dataclasses import dataclass, field

import numpy as np

from pizero_ray.bench.plans import LOW_RANK, bench_config
from pizero_ray.config import Config

MODES = {"exact": 0, "low_rank": LOW_RANK}  # mode -> perturbation rank
ROW_FIELDS = ("population", "mode", "planner", "simulations", "chunk_size", "chunks_per_launch", "overrides",
              "agent_steps_per_s", "iteration_s", "compile_s", "warmup_s", "device_memory_bytes", "platform",
              "program_loops", "device_calls_per_iteration")


@dataclass(frozen=True)
class SweepPoint:
    """One measurement: a population (antithetic pairs) of the bench's agent, and what differs from it."""

    population: int
    mode: str = "low_rank"  # "exact" (full-rank noise) or "low_rank" (rank LOW_RANK)
    planner: str = "muzero"  # or "none"
    simulations: int = 10
    chunk_size: int = 256  # the largest divisor of the population not above it is used
    overrides: dict = field(default_factory=dict)  # other Config settings, e.g. {"episode_loop": "horizon"}

    def config(self) -> Config:
        """The bench's agent at this point. Unless the overrides set ``chunks_per_launch``, the whole population
        is one launch: one device call, as a GPU worker given all its chunks."""
        if self.mode not in MODES:
            raise ValueError(f"unknown mode {self.mode!r} (choose from {', '.join(MODES)})")
        config = bench_config(self.population, self.chunk_size, self.simulations, perturbation_rank=MODES[self.mode],
                              planner=self.planner, **self.overrides)
        if "chunks_per_launch" not in self.overrides:
            config = dataclasses.replace(config, chunks_per_launch=config.population // config.chunk_size)
        return config

    def label(self) -> str:
        extra = "".join(f", {key}={value}" for key, value in self.overrides.items())
        return f"{self.population} pairs, {self.mode}, {self.planner}, {self.simulations} sims{extra}"


def as_point(point: SweepPoint | dict) -> SweepPoint:
    return point if isinstance(point, SweepPoint) else SweepPoint(**point)


def population_sweep(points, repeats: int, progress=print) -> list[dict]:
    """One row per point (``ROW_FIELDS``, or the point and its ``error``), timed one after another."""
    loops_by_program: dict[str, dict] = {}
    return [sweep_row(as_point(point), repeats, loops_by_program, progress) for point in points]


def sweep_row(point: SweepPoint, repeats: int, loops_by_program: dict[str, dict], progress=print) -> dict:
    """A point's row; its error in one line (and the sweep goes on) if it cannot be built or run."""
    progress(f"population sweep: {point.label()}")
    row = {**dataclasses.asdict(point), "platform": _platform()}
    try:
        config = point.config()
        row.update(time_population(config, repeats), chunk_size=config.chunk_size,
                   chunks_per_launch=config.chunks_per_launch)
        row["program_loops"] = program_loops(config, loops_by_program)
    except Exception as error:  # noqa: BLE001 - out of memory, a bad setting: recorded, the sweep goes on
        row["error"] = one_line(error)
    finally:
        gc.collect()  # the point's device buffers go before the next point allocates its own
    row["device_memory_bytes"] = peak_device_bytes()
    return row


def time_population(config: Config, repeats: int) -> dict:
    """The whole population scored on one device in one ``score_many`` call: compile, warm-up, median."""
    from pizero_ray import envs
    from pizero_ray.es import population
    from pizero_ray.trainer import chunk_scoring

    theta = np.asarray(population.flat_params(config, envs.make(config.env, **config.env_kwargs()))[0])
    started = time.perf_counter()
    scorer = chunk_scoring.ChunkScorer(config, max_devices=1)
    scorer.wait_until_compiled()
    compile_s = time.perf_counter() - started
    first_pairs = list(range(0, config.population, config.chunk_size))

    def one_iteration(seed: int) -> float:
        started = time.perf_counter()
        scores = scorer.score_many(theta, seed, first_pairs)  # on the host when it returns
        if len(scores) != len(first_pairs) or not all(np.isfinite(s).all() for s in scores):
            raise RuntimeError(f"score_many returned {len(scores)} chunks for {len(first_pairs)}, or non-finite scores")
        return time.perf_counter() - started

    warmup_s = one_iteration(0)  # a program compiled at the first call (if score_many makes one) is timed here
    calls_before = scorer.launches_run
    times = [one_iteration(seed) for seed in range(1, repeats + 1)]
    iteration_s = statistics.median(times)
    return {"agent_steps_per_s": scorer.agent_steps_per_pair * config.population / iteration_s,
            "iteration_s": iteration_s, "iteration_s_each": times, "compile_s": compile_s, "warmup_s": warmup_s,
            "repeats": repeats, "chunks": len(first_pairs), "parameters": scorer.parameters,
            "device_calls_per_iteration": (scorer.launches_run - calls_before) / repeats}


def program_loops(config: Config, known: dict[str, dict]) -> dict:
    """``rollout.pair_scorer_loops`` of the program the point runs: the pair scorer at a launch's pairs (a chunk's
    without ``chunks_per_launch``), lowered as the scorer lowers it, so that with a compile cache the scorer's
    program is loaded rather than compiled again. Computed once per program (``known``)."""
    from pizero_ray.bench.rollout import pair_scorer_loops

    launch_pairs = config.chunk_size * config.chunks_per_launch
    program = dataclasses.replace(config, population=launch_pairs, chunk_size=launch_pairs, chunks_per_launch=1)
    key = program.to_json()
    if key not in known:
        try:
            known[key] = pair_scorer_loops(program)
        except Exception as error:  # noqa: BLE001 - the timing stands without it
            known[key] = {"error": one_line(error)}
    return known[key]


def peak_device_bytes() -> int | None:
    """The default device's peak bytes in use so far, where JAX reports it (GPUs), else None."""
    import jax

    try:
        stats = jax.local_devices()[0].memory_stats()
    except Exception:  # noqa: BLE001 - a backend without memory statistics
        return None
    return int(stats["peak_bytes_in_use"]) if stats and "peak_bytes_in_use" in stats else None


def _platform() -> str:
    import jax

    return jax.local_devices()[0].platform


def one_line(error: BaseException) -> str:
    text = str(error).strip().splitlines()
    return f"{type(error).__name__}: {text[0] if text else ''}"[:400]


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description="time the population rollout at each point of a JSON list")
    parser.add_argument("--points", required=True, help="JSON file: a list of SweepPoint fields")
    parser.add_argument("--rows", required=True, help="JSON-lines file each row is appended to when measured")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--compile-cache", help="JAX persistent compile cache dir (default: none)")
    args = parser.parse_args(argv)
    from pizero_ray.trainer import compile_cache

    compile_cache.enable(args.compile_cache)
    loops_by_program: dict[str, dict] = {}
    progress = lambda line: print(line, file=sys.stderr, flush=True)  # noqa: E731
    with open(args.rows, "a") as rows:
        for point in json.load(open(args.points)):
            rows.write(json.dumps(sweep_row(as_point(point), args.repeats, loops_by_program, progress)) + "\n")
            rows.flush()
    return 0


if __name__ == "__main__":
    sys.exit(main())
