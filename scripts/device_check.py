#!/usr/bin/env python3
"""`make device-check`: the project's checks on an NVIDIA GPU, one command, under 8 minutes.

1. Python with the ``gpu`` extra: ``make install`` and ``pip install -e '.[gpu]'``
   into .venv; or, on an offline GPU machine, ``--python`` names an interpreter
   that already has a CUDA JAX and ``--wheels DIR`` holds wheels of whatever it
   lacks (scripts/fetch-device-wheels.sh makes that folder).
2. The tests marked ``gpu`` (tests/trainer/test_gpu.py): kept and regenerated noise
   bit-identical on the GPU, and the same parameter hash with 1 and 2 GPU workers.
3. Whether the CPU and the GPU draw the same noise bits (a driver without a GPU
   regenerates the noise of a chunk whose GPU worker died).
4. ``pizero bench --quick --json`` with the Ray trainer's workers on the GPU.
5. TSP and Collect trainings with ``--gpus-per-worker 1``, each stopped by SIGTERM
   at its wall-clock budget (pizero checkpoints and exits), then evaluated.
6. One JSON under docs/bench/, and a summary on stdout.

Without a GPU it says so and exits 0. Each step has a deadline and records
its own outcome, so one failing step still leaves the others' measurements.
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import tempfile
import time
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

sys.path.insert(0, str(ROOT))
from pizero_ray.storage.run_dir import read_metrics  # noqa: E402  (pure Python: no JAX on the host needed)

TRAININGS = (("tsp", ()), ("collect", ()))  # (env, extra train options)


NOISE_PROBE = """
import json, jax, numpy as np
from pizero_ray import es
from pizero_ray.es import population
from pizero_ray.config import build_config
from pizero_ray import envs
config = build_config("default", env="tsp")
_, layout = population.flat_params(config, envs.make("tsp"))
parts = es.gradient_parts(config, layout.perturbation)
drawn = {}
for platform in ("cpu", "gpu"):
    with jax.default_device(jax.devices(platform)[0]):
        drawn[platform] = np.asarray(parts.noise(np.uint32(7), np.int32(64)))
differ = drawn["cpu"] != drawn["gpu"]
print(json.dumps({"noise_values": int(differ.size), "differing_values": int(differ.sum()),
                  "max_abs_difference": float(np.abs(drawn["cpu"] - drawn["gpu"]).max())}))
"""


def noise_across_backends(python: str, env: dict) -> dict:
    """Step 3: one chunk's noise drawn on the CPU and on the GPU by the same jitted function."""
    outcome = run([python, "-c", NOISE_PROBE], env, 300)
    if outcome["exit_code"] == 0:
        outcome.update(json.loads(outcome["output_tail"].strip().splitlines()[-1]))
    return outcome


def train_for(python: str, env: dict, name: str, extra: tuple, seconds: float, gpus: float, out: Path) -> dict:
    """Step 5 for one environment: train until SIGTERM at ``seconds``, then evaluate on 1,000 episodes."""
    run_dir = out / f"run-{name}"
    command = [python, "-m", "pizero_ray.cli", "train", "--env", name, "--run-dir", str(run_dir),
               "--iterations", "1000000", "--workers", "1", "--gpus-per-worker", str(gpus),
               "--checkpoint-every", "50", "--no-progress", "--compile-cache", str(out / "jax-cache"), *extra]
    started = time.time()
    process = subprocess.Popen(command, cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                               text=True, start_new_session=True)
    try:
        text, _ = process.communicate(timeout=seconds)
    except subprocess.TimeoutExpired:
        text = stop(process)  # pizero saves a checkpoint and exits 143
    result = {"env": name, "budget_s": seconds, "wall_s": round(time.time() - started, 1),
              "exit_code": process.returncode, "final": last_json(text), "output_tail": text[-1500:]}
    rows = read_metrics(run_dir)
    if rows:
        steady = sorted(row["iteration_time_s"] for row in rows[len(rows) // 2:])
        result.update(iterations=rows[-1]["iteration"], first_mean_score=rows[0]["mean_score"],
                      last_mean_score=rows[-1]["mean_score"], median_iteration_s=steady[len(steady) // 2],
                      first_iteration_s=rows[0]["iteration_time_s"])
        evaluation = run([python, "-m", "pizero_ray.cli", "eval", str(run_dir), "--episodes", "1000", "--json"],
                         env, 300)
        result["eval"] = last_json(evaluation["output_tail"]) or evaluation
    return result


def save(args, report: dict) -> Path:
    """Writes the report so far: a step that hangs past the command's own limit still leaves the others'."""
    return save_report(report_path(args.out, report, "device-check"), report)


def check(args) -> dict:
    gpus = gpu_names()
    if not gpus and not args.cpu_rehearsal:
        print("device-check: no NVIDIA GPU on this machine (nvidia-smi lists none): nothing to check")
        raise SystemExit(0)
    python, env, installed = python_environment(args)
    out = Path(tempfile.mkdtemp(prefix="pizero-device-check-"))
    report = report_header(gpus, installed)
    steps = [
        ("gpu_tests", lambda: run([python, "-m", "pytest", "-q", "-m", "gpu", "-p", "no:cacheprovider",
                                   "tests/trainer/test_gpu.py"], env, args.test_seconds)),
        ("noise_cpu_vs_gpu",
         lambda: {"skipped": "no GPU"} if args.cpu_rehearsal else noise_across_backends(python, env)),
        ("bench", lambda: _bench(python, env, args)),
    ] + [(f"train_{name}", lambda name=name, extra=extra: train_for(
        python, env, name, extra, args.train_seconds, 0.0 if args.cpu_rehearsal else 1.0, out))
        for name, extra in TRAININGS]
    for name, step in steps:
        print(f"device-check: {name} ...", file=sys.stderr, flush=True)
        report[name] = step()
        save(args, report)
        print(f"device-check: {name}: {_summary(name, report[name])}", file=sys.stderr, flush=True)
    return report


def _bench(python: str, env: dict, args) -> dict:
    command = [python, "-m", "pizero_ray.cli", "bench", "--quick", "--json",
               "--gpus", "0" if args.cpu_rehearsal else "1"]
    outcome = run(command, env, args.bench_seconds)
    outcome["result"] = last_json(outcome["output_tail"]) if outcome["exit_code"] == 0 else None
    return outcome


def _summary(name: str, result: dict) -> str:
    if name == "gpu_tests":
        counts = re.findall(r"\d+ (?:passed|failed|skipped|error)", result["output_tail"])
        return ", ".join(counts) or f"exit {result['exit_code']}"
    if name == "noise_cpu_vs_gpu":
        return f"{result.get('differing_values', '?')} of {result.get('noise_values', '?')} values differ"
    if name == "bench":
        bench = result.get("result") or {}
        return (f"exit {result['exit_code']}, {result['seconds']} s; rollout agent-steps/s "
                f"{bench.get('rollout_agent_steps_per_s', '?')}, trainer iteration (2 workers) "
                f"{bench.get('trainer_iteration_s_2_workers', '?')} s")
    evaluation = result.get("eval") or {}
    return (f"{result.get('iterations', 0)} iterations in {result['wall_s']} s "
            f"(median {result.get('median_iteration_s', '?')} s), eval {evaluation.get('mean_score', '?')}")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--python", help="an interpreter with a CUDA JAX and the project's dependencies "
                        "(default: install the gpu extra into .venv)")
    parser.add_argument("--wheels", help="offline: a folder of wheels of what --python lacks")
    parser.add_argument("--train-seconds", type=float, default=75.0,
                        help="wall-clock budget of each training, its start and compile included")
    parser.add_argument("--bench-seconds", type=float, default=150.0)
    parser.add_argument("--test-seconds", type=float, default=150.0)
    parser.add_argument("--out", default=str(ROOT / "docs" / "bench"), help="folder for the JSON")
    parser.add_argument("--cpu-rehearsal", action="store_true", help="run every step on the CPU (tests the script)")
    args = parser.parse_args(argv)
    started = time.time()
    report = check(args)
    report["total_s"] = round(time.time() - started, 1)
    path = save(args, report)
    print(json.dumps({name: _summary(name, report[name]) for name in report
                      if name == "gpu_tests" or name.startswith(("noise", "bench", "train_"))}, indent=2))
    print(f"device-check: wrote {path} ({report['total_s']} s)")
    failed = report["gpu_tests"]["exit_code"] != 0 and not args.cpu_rehearsal
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
