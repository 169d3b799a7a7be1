#!/usr/bin/env python3
"""`make device-run`: does the GPU pay? One prepared run of about 8 minutes on one NVIDIA GPU.

Default run, each step with its own deadline (a share of what is left of ``--budget-s``), the report saved
after every step into OUT/<date>-device-run-<gpu kind>.json, so a run cut off keeps what it measured:

a. gpu_tests: ``pytest -m gpu tests/trainer/test_gpu.py`` (skipped in a CPU rehearsal).
b. population_sweep: the population rollout in this machine's one device (``pizero_ray.bench.population_sweep``, in a
   subprocess): the main curve, low-rank noise + MuZero planner + 10 simulations at 64 to 32768 pairs, then
   cross sections at 8192 pairs: full-rank noise, no planner, episode_loop=horizon, simulation_loop=unrolled and both.
c. population_sweep_command_buffers: the cross-section points again (and their base point) in a subprocess with XLA's
   command buffers for while loops and conditionals (COMMAND_BUFFER_FLAGS), which should spare the host
   round trip per trip of a while loop. An XLA that rejects the flags leaves the error in the rows.
d. trainer: ``pizero train`` with Ray, one worker on the whole GPU, then two sharing it, at the sweep's
   agent at the gpu preset's population, chunks and launches; the later half's median iteration and driver
   update (metrics.jsonl), both parameter hashes, and the iteration over the in-process rollout of the same
   population (step b).

``--learn ENV[,ENV]`` is a second invocation instead: ``--seeds`` trainings of each environment at once
(separate processes sharing the GPU), the ``default`` preset at ``--population``, each stopped by SIGTERM
after ``--seconds`` (pizero checkpoints and exits), then evaluated on 1,000 episodes; into
OUT/<date>-device-learn-<gpu kind>.json.

``--cpu-rehearsal`` runs it all on the CPU at small sizes (tests the script); ``--smoke`` smaller still, a
tiny agent (the suite's test of this script). Without a GPU and neither flag, it says so and exits 0. It
exits 1 only if the GPU tests fail on a GPU.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

from device_common import (
    ROOT,
    gpu_names,
    last_json,
    python_environment,
    report_header,
    report_path,
    run,
    save_report,
    stop,
)

# The Config's declared settings and the bench's agent, as plain data: this process builds no Config (checking
# one imports the environments, and JAX); the subprocesses do.
sys.path.insert(0, str(ROOT))
from pizero_ray.bench.plans import BENCH_AGENT, LOW_RANK  # noqa: E402
from pizero_ray.config import Config, largest_divisor_at_most  # noqa: E402
from pizero_ray.presets import PRESETS  # noqa: E402
from pizero_ray.settings import lookup  # noqa: E402
from pizero_ray.storage.run_dir import read_metrics  # noqa: E402

MAIN_POPULATIONS = (64, 256, 1024, 4096, 8192, 16384, 32768)
# The trainer check runs the gpu preset's population and chunks (launches of half the chunks: the preset's 32 of
# 64 at its population), so that its figures are the preset's.
GPU_PRESET = PRESETS["gpu"]
CROSS_POPULATION = 8192
COMMAND_BUFFER_FLAGS = ("--xla_gpu_enable_command_buffer=FUSION,CUBLAS,CUBLASLT,CUSTOM_CALL,CUDNN,WHILE,CONDITIONAL "
                        "--xla_gpu_graph_min_graph_size=1")
# Each step's share of the time left when it starts; a step that ends early leaves its time to the next ones.
# The GPU tests are a gate (a cut-off run fails them), the sweep the main measurement: the larger shares.
STEP_SHARES = {"gpu_tests": 0.25, "population_sweep": 0.35, "population_sweep_command_buffers": 0.12, "trainer": 0.28}
LOOP_SETTINGS = {"episode_loop": "horizon", "simulation_loop": "unrolled"}  # each, then both
TINY_AGENT = {"hidden_size": 8, "latent_size": 8, "memory_size": 8, "num_abstract_actions": 2}
TARGET_AGENT_STEPS_PER_S = 1e6
TARGET_TRAINER_OVER_ROLLOUT = 1.25
TARGET_UPDATE_SHARE = 0.10


CROSS_SECTIONS = ("exact", "no_planner", "episode_loop", "simulation_loop", "both_loops")


@dataclass(frozen=True)
class Plan:
    """The sizes of one default run."""

    populations: tuple[int, ...]  # the main curve (pairs)
    cross_population: int
    chunk_size: int
    simulations: int
    repeats: int
    trainer_population: int
    trainer_chunk_size: int
    trainer_iterations: int
    gpus_per_worker: float  # the single worker's; two workers take half each
    agent: dict = field(default_factory=dict)  # Config overrides of every point and training (smoke: a tiny agent)
    cross_sections: tuple[str, ...] = CROSS_SECTIONS
    trainer_chunks_per_launch: int | None = None  # None: half the chunks


def plan_for(args) -> Plan:
    """The GPU's sizes, the rehearsal's or the smoke test's; the command line's where given."""
    if args.smoke:  # a tiny agent, one point and no cross section: the whole path in under a minute on 2 cores
        plan = Plan((8,), 8, 4, 2, 2, 8, 4, 2, 0.0, dict(TINY_AGENT), ())
    elif args.cpu_rehearsal:
        plan = Plan((16, 64), 64, 16, 10, 3, 64, 16, 3, 0.0)
    else:
        plan = Plan(MAIN_POPULATIONS, CROSS_POPULATION, 256, 10, 3, GPU_PRESET["population"], GPU_PRESET["chunk_size"],
                    8, 1.0)
    given = {"chunk_size": args.chunk_size, "repeats": args.repeats, "trainer_population": args.trainer_population,
             "trainer_chunk_size": args.trainer_chunk_size, "trainer_iterations": args.trainer_iterations,
             "trainer_chunks_per_launch": args.trainer_chunks_per_launch}
    return dataclasses.replace(plan, **{name: value for name, value in given.items() if value is not None})


def sweep_point(plan: Plan, population: int, **changes) -> dict:
    """A point of population_sweep: the plan's main agent (low-rank noise, MuZero planner) with ``changes``."""
    overrides = {**plan.agent, **changes.pop("overrides", {})}
    return {"population": population, "mode": "low_rank", "planner": "muzero", "simulations": plan.simulations,
            "chunk_size": plan.chunk_size, "overrides": overrides, **changes}


def trainer_point(plan: Plan) -> dict:
    """The trainings' config as a sweep point (step b times it: the rollout the trainer is held to).

    A launch is half the chunks unless told: one worker plays its
    call of all chunks as two launches, two workers one launch each, and both runs have the same config (the
    launch is part of what is computed), so their hashes can be compared.
    """
    chunks = plan.trainer_population // bench_chunk(plan.trainer_population, plan.trainer_chunk_size)
    launch = plan.trainer_chunks_per_launch or largest_divisor_at_most(chunks, chunks // 2)
    return sweep_point(plan, plan.trainer_population, chunk_size=plan.trainer_chunk_size,
                       overrides={"chunks_per_launch": launch})


def sweep_points(plan: Plan) -> tuple[list[dict], list[dict]]:
    """(main curve and the trainer's point, cross sections): the cross sections' first point is their base, the
    main agent at the cross population (which step b measures once, on the main curve)."""
    def point(population: int, **changes) -> dict:
        return sweep_point(plan, population, **changes)

    changes = {"exact": {"mode": "exact"}, "no_planner": {"planner": "none"},
               "episode_loop": {"overrides": {"episode_loop": LOOP_SETTINGS["episode_loop"]}},
               "simulation_loop": {"overrides": {"simulation_loop": LOOP_SETTINGS["simulation_loop"]}},
               "both_loops": {"overrides": dict(LOOP_SETTINGS)}}
    main = [point(population) for population in plan.populations]
    main.append(point(max(plan.populations), planner="none"))  # the planner-free agent's target: 10M agent-steps/s
    main += [trainer_point(plan)] if trainer_point(plan) not in main else []
    cross = [point(plan.cross_population)] + [point(plan.cross_population, **changes[name])
                                              for name in plan.cross_sections if name in changes]
    return main, cross


def sweep_step(python: str, env: dict, points: list[dict], repeats: int, deadline_s: float, work: Path,
               xla_flags: str | None = None) -> dict:
    """The points timed in a subprocess (its own XLA_FLAGS), one row each. A process that dies (out of memory
    beyond what JAX can report) costs the point it was on; the rest go on in a new process. Points the
    deadline leaves unmeasured say so."""
    started, env = time.time(), dict(env)
    if xla_flags:  # added to, not replacing, flags already set (the test suite's compile flags)
        env["XLA_FLAGS"] = f"{env.get('XLA_FLAGS', '')} {xla_flags}".strip()
    work.mkdir(parents=True, exist_ok=True)
    rows_path, rows, processes = work / "rows.jsonl", [], []
    while len(rows) < len(points) and time.time() - started < deadline_s:
        (work / "points.json").write_text(json.dumps(points[len(rows):]))
        rows_path.write_text("")
        outcome = run([python, "-m", "pizero_ray.bench.population_sweep", "--points", str(work / "points.json"),
                       "--rows", str(rows_path), "--repeats", str(repeats),
                       "--compile-cache", str(work.parent / "jax-cache")],  # shared with the trainer's workers
                      env, deadline_s - (time.time() - started))
        rows += [json.loads(line) for line in rows_path.read_text().splitlines() if line.strip()]
        processes.append({k: v for k, v in outcome.items() if k != "output_tail"})
        if len(rows) < len(points) and not outcome["timed_out"]:  # it died on this point
            rows.append({**points[len(rows)], "error": f"the sweep process died (exit {outcome['exit_code']}): "
                         f"{_last_line(outcome['output_tail'])}"})
        processes[-1]["output_tail"] = outcome["output_tail"][-800:]
    rows += [{**p, "error": f"not measured: the step's {deadline_s:.0f} s ran out"} for p in points[len(rows):]]
    return {"xla_flags": env.get("XLA_FLAGS", ""), "deadline_s": round(deadline_s, 1), "rows": rows,
            "processes": processes, "seconds": round(time.time() - started, 1),
            "note": "device_memory_bytes: the process's peak so far (not the point's alone); compile_s: building "
                    "the scorer (its programs compiled, or loaded from the compile cache that the points and the "
                    "trainer's workers share); warmup_s: the first call (with any program compiled on first use)"}


def _last_line(text: str) -> str:
    lines = [line for line in text.strip().splitlines() if line.strip()]
    return lines[-1][:300] if lines else "(no output)"


def bench_chunk(population: int, chunk_size: int) -> int:
    """The chunk bench_config makes of a chunk size: the largest divisor of the population not above it."""
    return largest_divisor_at_most(population, max(1, min(chunk_size, population)))


def train_flags(settings: dict) -> list[str]:
    """`pizero train` options setting these Config settings (by field name)."""
    flags = []
    for name, value in settings.items():
        flag = lookup(Config, name).flag
        if flag is None or isinstance(value, (bool, dict, list, tuple)):
            raise ValueError(f"device-run: cannot pass {name}={value!r} to pizero train")
        flags += [flag, str(value)]
    return flags


def train_command(python: str, plan: Plan, run_dir: Path, workers: int, gpus: float, cache: Path) -> list[str]:
    """`pizero train` of step b's trainer point (bench_config's agent: the default preset on TSP10 with the
    settings below), every worker's chunks in one call."""
    point = trainer_point(plan)
    chunk = bench_chunk(point["population"], point["chunk_size"])
    settings = {**BENCH_AGENT, "num_simulations": point["simulations"], "root_noise": 0.0, "planner": point["planner"],
                "perturbation_rank": LOW_RANK, **point["overrides"]}
    chunks_per_call = -(-point["population"] // chunk // workers)
    return [python, "-m", "pizero_ray.cli", "train", "--env", "tsp", "--preset", "default", "--run-dir", str(run_dir),
            "--population", str(point["population"]), "--chunk-size", str(chunk), *train_flags(settings),
            "--iterations", str(plan.trainer_iterations), "--workers", str(workers), "--gpus-per-worker", f"{gpus:g}",
            "--chunks-per-call", str(chunks_per_call), "--checkpoint-every", "0", "--no-progress",
            "--compile-cache", str(cache)]


def later_half_median(rows: list[dict], key: str) -> float | None:
    values = [row[key] for row in rows[len(rows) // 2:] if key in row]
    return statistics.median(values) if values else None


def trainer_run(python: str, env: dict, plan: Plan, workers: int, gpus: float, deadline_s: float, work: Path) -> dict:
    """One training; its iteration and update times from metrics.jsonl (the later half's medians) and its hash."""
    run_dir = work / f"train-{workers}-workers"
    outcome = run(train_command(python, plan, run_dir, workers, gpus, work / "jax-cache"), env, deadline_s)
    rows = read_metrics(run_dir)
    iteration_s, update_s = later_half_median(rows, "iteration_time_s"), later_half_median(rows, "update_time_s")
    final = last_json(outcome["output_tail"]) or {}
    return {"workers": workers, "gpus_per_worker": gpus, "exit_code": outcome["exit_code"],
            "timed_out": outcome["timed_out"], "seconds": outcome["seconds"], "command": outcome["command"],
            "iterations": len(rows), "iteration_s_each": [round(r["iteration_time_s"], 4) for r in rows],
            "median_iteration_s": iteration_s, "median_update_s": update_s,
            "update_share": update_s / iteration_s if iteration_s and update_s is not None else None,
            "gradient_parts_on_driver": rows[-1].get("gradient_parts_on_driver") if rows else None,
            "parameter_hash": final.get("parameter_hash"),
            **({} if outcome["exit_code"] == 0 else {"output_tail": outcome["output_tail"][-1500:]})}


def trainer_step(python: str, env: dict, plan: Plan, rollout: dict | None, deadline_s: float, work: Path) -> dict:
    """One GPU worker, then two sharing the GPU: iteration, driver update share, hashes, and the ratio to the
    in-process rollout of the same population (``rollout``: step b's row, None if it has none)."""
    started = time.time()
    one = trainer_run(python, env, plan, 1, plan.gpus_per_worker, deadline_s / 2, work)
    two = trainer_run(python, env, plan, 2, plan.gpus_per_worker / 2, deadline_s - (time.time() - started), work)
    rollout_s = rollout.get("iteration_s") if rollout else None
    return {
        "population": plan.trainer_population, "chunk_size": plan.trainer_chunk_size, "one_worker": one,
        "two_workers": two, "hashes_equal": one["parameter_hash"] is not None
        and one["parameter_hash"] == two["parameter_hash"],
        "rollout_iteration_s": rollout_s,
        "iteration_over_rollout": one["median_iteration_s"] / rollout_s if rollout_s and one["median_iteration_s"]
        else None,
        "update_time_note": "metrics.jsonl's update_time_s: from the last chunk's scores to the new parameters "
                            "(the weights, every chunk's gradient part gathered from the workers that kept its noise "
                            "or regenerated in the driver, and the Adam step); iteration_time_s: the whole "
                            "iteration; both the medians of the later half of the iterations",
        "seconds": round(time.time() - started, 1)}


def main_rollout_row(rows: list[dict], plan: Plan) -> dict | None:
    """Step b's row of the trainings' config (``trainer_point``): the rollout the trainer is held to."""
    point = {**trainer_point(plan), "chunk_size": bench_chunk(plan.trainer_population, plan.trainer_chunk_size)}
    for row in rows:
        if "error" not in row and all(row.get(key) == value for key, value in point.items()):
            return row
    return None


def targets(report: dict) -> dict:
    """Issue 46's targets, each met or not (None: not measured)."""
    plan = report["plan"]
    main = [row for row in report.get("population_sweep", {}).get("rows", []) if "agent_steps_per_s" in row and (
        row["mode"], row["planner"], row["simulations"], row["overrides"]) == ("low_rank", "muzero",
                                                                            plan["simulations"], plan["agent"])]
    trainer = report.get("trainer", {})
    best = max((row["agent_steps_per_s"] for row in main), default=None)
    ratio, share = trainer.get("iteration_over_rollout"), (trainer.get("one_worker") or {}).get("update_share")
    return {
        "best_rollout_agent_steps_per_s": best,
        "rollout_reaches_1m_agent_steps_per_s": None if best is None else best >= TARGET_AGENT_STEPS_PER_S,
        "trainer_iteration_within_1.25x_rollout": None if ratio is None else ratio <= TARGET_TRAINER_OVER_ROLLOUT,
        "driver_update_within_10_percent": None if share is None else share <= TARGET_UPDATE_SHARE,
        "hashes_equal_1_and_2_workers": trainer.get("hashes_equal"),
    }


def default_run(args, python: str, env: dict, report: dict, path: Path) -> dict:
    """Steps a to d, each to its share of the time left, the report saved after each."""
    plan, started, work = plan_for(args), time.time(), Path(tempfile.mkdtemp(prefix="pizero-device-run-"))
    main, cross = sweep_points(plan)
    report.update(plan=dataclasses.asdict(plan), budget_s=args.budget_s)
    steps = {
        "gpu_tests": lambda deadline: {"skipped": "CPU rehearsal"} if args.cpu_rehearsal or args.smoke else run(
            [python, "-m", "pytest", "-q", "-m", "gpu", "-p", "no:cacheprovider", "tests/trainer/test_gpu.py"],
            env, deadline),
        "population_sweep": lambda deadline: sweep_step(
            python, env, main + [p for p in cross if p not in main], plan.repeats, deadline, work / "sweep"),
        "population_sweep_command_buffers": lambda deadline: sweep_step(
            python, env, cross, plan.repeats, deadline, work / "sweep-command-buffers", COMMAND_BUFFER_FLAGS),
        "trainer": lambda deadline: trainer_step(
            python, env, plan, main_rollout_row(report["population_sweep"]["rows"], plan), deadline, work),
    }
    for name, step in steps.items():
        left = args.budget_s - (time.time() - started)
        deadline = left * STEP_SHARES[name] / sum(STEP_SHARES[later] for later in list(steps)[list(steps).index(name):])
        _say(f"{name} (deadline {deadline:.0f} s) ...")
        report[name] = step(deadline)
        report["targets"] = targets(report)
        save_report(path, report)
        _say(f"{name}: {summary(name, report[name])}")
    return report


def summary(name: str, result: dict) -> str:
    """One line of a step's outcome."""
    if "skipped" in result:
        return f"skipped ({result['skipped']})"
    if name == "gpu_tests":
        return f"exit {result['exit_code']} in {result['seconds']} s: {_last_line(result['output_tail'])}"
    if name.startswith("population_sweep"):
        done = [row for row in result["rows"] if "agent_steps_per_s" in row]
        best = max(done, key=lambda row: row["agent_steps_per_s"], default=None)
        top = (f"; best {best['agent_steps_per_s']:,.0f} agent-steps/s ({best['population']} pairs, {best['mode']}, "
               f"planner {best['planner']})") if best else ""
        return f"{len(done)} of {len(result['rows'])} points in {result['seconds']} s{top}"
    if name == "trainer":
        one, two = result["one_worker"], result["two_workers"]
        return (f"iteration {one['median_iteration_s']} s (1 worker), {two['median_iteration_s']} s (2 workers); "
                f"over the rollout {result['iteration_over_rollout']}; update share {one['update_share']}; "
                f"hashes equal: {result['hashes_equal']}")
    return json.dumps(result)[:300]


def _say(line: str) -> None:
    print(f"device-run: {line}", file=sys.stderr, flush=True)


def learn_command(python: str, args, env_name: str, seed: int, run_dir: Path, cache: Path) -> list[str]:
    """`pizero train` of one seed: ``--preset`` at ``--population``, every chunk in one call and one launch, its worker
    on its share of the GPU (each seed's own local Ray instance sees the whole GPU; the share says the intent
    and turns off JAX's preallocation in the worker)."""
    chunk = bench_chunk(args.population, args.learn_chunk_size)
    chunks = args.population // chunk
    gpus = 0.0 if args.cpu_rehearsal or args.smoke else int(10_000 / args.seeds) / 10_000  # Ray: 4 decimals
    launch = ["--chunks-per-launch", str(chunks)]
    return [python, "-m", "pizero_ray.cli", "train", "--env", env_name, "--preset", args.preset,
            "--run-dir", str(run_dir), "--population", str(args.population), "--chunk-size", str(chunk), *launch,
            "--seed", str(seed), "--iterations", "1000000", "--workers", "1", "--gpus-per-worker", f"{gpus:g}",
            "--chunks-per-call", str(chunks), "--checkpoint-every", "50", "--no-progress",
            "--compile-cache", str(cache)]


def stop_at(processes: list[subprocess.Popen], seconds: float) -> list[str]:
    """Waits ``seconds`` in all, then SIGTERMs whoever still runs (pizero checkpoints and exits) and gives
    each a minute; their outputs."""
    started = time.time()
    for process in processes:
        try:
            process.wait(timeout=max(0.0, seconds - (time.time() - started)))
        except subprocess.TimeoutExpired:
            pass
    for process in processes:  # every one signalled before any is waited for: they stop side by side
        if process.poll() is None:
            process.send_signal(signal.SIGTERM)
    return [stop(process) for process in processes]


def learn_env(python: str, env: dict, args, env_name: str, work: Path) -> dict:
    """``--seeds`` trainings of one environment at once for ``--seconds``, then each evaluated."""
    started, run_dirs = time.time(), [work / f"{env_name}-seed-{seed}" for seed in range(args.seeds)]
    processes = [subprocess.Popen(learn_command(python, args, env_name, seed, run_dir, work / "jax-cache"), cwd=ROOT,
                                  env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                                  start_new_session=True) for seed, run_dir in enumerate(run_dirs)]
    outputs = stop_at(processes, args.seconds)
    trained_s = round(time.time() - started, 1)
    evaluations = [subprocess.Popen([python, "-m", "pizero_ray.cli", "eval", str(run_dir), "--episodes",
                                     str(args.eval_episodes), "--json"], cwd=ROOT, env=env, stdout=subprocess.PIPE,
                                    stderr=subprocess.STDOUT, text=True, start_new_session=True)
                   for run_dir in run_dirs]
    evaluated = stop_at(evaluations, 300)
    seeds = [learned(seed, run_dirs[seed], processes[seed].returncode, outputs[seed], evaluated[seed])
             for seed in range(args.seeds)]
    return {"env": env_name, "population": args.population, "budget_s": args.seconds, "trained_s": trained_s,
            "seconds": round(time.time() - started, 1), "seeds": seeds}


def learned(seed: int, run_dir: Path, exit_code: int, output: str, evaluation: str) -> dict:
    """One seed's training and evaluation, from its metrics.jsonl and the two commands' last JSON lines."""
    rows = read_metrics(run_dir)
    return {"seed": seed, "exit_code": exit_code, "final": last_json(output), "iterations": len(rows),
            "first_mean_score": rows[0]["mean_score"] if rows else None,
            "last_mean_scores": [row["mean_score"] for row in rows[-5:]],
            "median_iteration_s": later_half_median(rows, "iteration_time_s"), "eval": last_json(evaluation),
            **({} if rows else {"output_tail": output[-1500:]})}


def learn(args, python: str, env: dict, report: dict, path: Path) -> dict:
    work = Path(tempfile.mkdtemp(prefix="pizero-device-learn-"))
    report.update(preset=args.preset, population=args.population, seconds=args.seconds, seeds=args.seeds, runs={})
    for env_name in args.learn:
        _say(f"learn {env_name}: {args.seeds} seeds for {args.seconds:g} s ...")
        report["runs"][env_name] = learn_env(python, env, args, env_name, work)
        save_report(path, report)
        scores = [(seed.get("eval") or {}).get("mean_score") for seed in report["runs"][env_name]["seeds"]]
        _say(f"learn {env_name}: iterations {[s['iterations'] for s in report['runs'][env_name]['seeds']]}, "
             f"eval mean scores {scores}")
    return report


def env_names(text: str) -> list[str]:
    names = [name.strip() for name in text.split(",") if name.strip()]
    if not names:
        raise argparse.ArgumentTypeError("give one or more environments, e.g. tsp,collect")
    return names


def parse_args(argv: list[str] | None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--python", help="an interpreter with a CUDA JAX and the project's dependencies "
                        "(default: install the gpu extra into .venv)")
    parser.add_argument("--wheels", help="offline: a folder of wheels of what --python lacks")
    parser.add_argument("--out", default=str(ROOT / "docs" / "bench"), help="folder for the JSON")
    parser.add_argument("--budget-s", type=float, help="the default run's seconds, set-up included (default 480; "
                        "900 in a CPU rehearsal, 240 with --smoke)")
    parser.add_argument("--cpu-rehearsal", action="store_true", help="every step on the CPU at small sizes")
    parser.add_argument("--smoke", action="store_true", help="a CPU rehearsal at the smallest sizes (the suite's)")
    sizes = parser.add_argument_group("sizes of the default run (defaults: the GPU's, or the rehearsal's)")
    sizes.add_argument("--chunk-size", type=_positive_int, help="the sweep's chunk (GPU default 256)")
    sizes.add_argument("--repeats", type=_positive_int, help="timed calls per sweep point, after a warm-up (3)")
    sizes.add_argument("--trainer-population", type=_positive_int, help="pairs (GPU default: the gpu preset's)")
    sizes.add_argument("--trainer-chunk-size", type=_positive_int, help="GPU default 256")
    sizes.add_argument("--trainer-iterations", type=_positive_int, help="GPU default 8")
    sizes.add_argument("--trainer-chunks-per-launch", type=_positive_int,
                       help="chunks per launch (default: half the chunks)")
    learning = parser.add_argument_group("--learn: trainings instead of the default run")
    learning.add_argument("--learn", type=env_names, metavar="ENV[,ENV]", help="train these environments")
    learning.add_argument("--preset", default="default", help="the trainings' preset (default: default)")
    learning.add_argument("--population", type=_positive_int, help="pairs (default 8192; 64 in a rehearsal)")
    learning.add_argument("--learn-chunk-size", type=_positive_int, help="default 256; 16 in a rehearsal")
    learning.add_argument("--seconds", type=float, help="each environment's training budget (default 300; 30 in a "
                          "rehearsal)")
    learning.add_argument("--seeds", type=_positive_int, default=3, help="trainings at once per environment (3)")
    learning.add_argument("--eval-episodes", type=_positive_int, default=1000)
    args = parser.parse_args(argv)
    small = args.cpu_rehearsal or args.smoke
    defaults = {"budget_s": 240.0 if args.smoke else 900.0 if args.cpu_rehearsal else 480.0,
                "population": 64 if small else 8192, "learn_chunk_size": 16 if small else 256,
                "seconds": 30.0 if small else 300.0}
    for name, value in defaults.items():
        if getattr(args, name) is None:
            setattr(args, name, value)
    if args.budget_s <= 0 or args.seconds <= 0:
        parser.error("--budget-s and --seconds must be positive")
    if args.preset not in PRESETS:
        parser.error(f"unknown preset {args.preset!r} (choose from {', '.join(PRESETS)})")
    return args


def _positive_int(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1:
        raise argparse.ArgumentTypeError(f"expected a positive integer, got {text!r}")
    return value


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    gpus = gpu_names()
    if not gpus and not (args.cpu_rehearsal or args.smoke):
        print("device-run: no NVIDIA GPU on this machine (nvidia-smi lists none): nothing to run "
              "(--cpu-rehearsal rehearses it on the CPU)")
        return 0
    args.cpu_rehearsal = args.cpu_rehearsal or args.smoke
    started = time.time()
    python, env, installed = python_environment(args, tool="device-run")
    report = report_header(gpus, installed)
    report["setup_s"] = round(time.time() - started, 1)
    what = "device-learn" if args.learn else "device-run"
    path = report_path(args.out, report, what)
    args.budget_s -= report["setup_s"]  # the default run's budget counts the set-up
    report = learn(args, python, env, report, path) if args.learn else default_run(args, python, env, report, path)
    report["total_s"] = round(time.time() - started, 1)
    save_report(path, report)
    if not args.learn:
        print(json.dumps({"targets": report["targets"], **{name: summary(name, report[name]) for name in STEP_SHARES}},
                         indent=2))
    print(f"device-run: wrote {path} ({report['total_s']} s)")
    gpu_tests = report.get("gpu_tests", {})
    return 1 if gpu_tests.get("exit_code", 0) != 0 and not args.cpu_rehearsal else 0


if __name__ == "__main__":
    sys.exit(main())
