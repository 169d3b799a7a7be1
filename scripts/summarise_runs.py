"""One JSON summary of training runs for the docs: curves, iteration times and held-out evaluations.

Usage::

    python scripts/summarise_runs.py --out docs/results/X.json --command "what was run" \
        LABEL=RUN_DIR[:EVAL_JSON] ...

EVAL_JSON is what ``pizero eval RUN_DIR --episodes 1000 --seed 0 --json`` wrote;
its mean and 95% interval are taken as it wrote them. The
curve is every learning-curve evaluation as [iteration, score, training
seconds]. Committed summaries keep a run's figures after its run dir is gone.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pizero_ray.storage import run_dir  # noqa: E402


def held_out(eval_path: Path) -> dict:
    evaluation = json.loads(eval_path.read_text())
    mean, (low, high) = evaluation["mean_score"], evaluation["ci95"]  # as pizero eval --json wrote them
    references = {k: v for k, v in evaluation.items() if k.endswith(("_score", "_length", "_covered", "_fraction"))
                  and k not in ("mean_score", "std_score") and isinstance(v, float)}
    return {"episodes": evaluation["episodes"], "seed": evaluation["seed"], "mean_score": round(mean, 4),
            "ci95": [round(low, 4), round(high, 4)], "references": references}


def summary(path: Path, eval_path: Path | None) -> dict:
    config = run_dir.read_config(path)
    rows = run_dir.read_metrics(path)
    evals = run_dir.evaluated_rows(path)
    times = [r["iteration_time_s"] for r in rows if "iteration_time_s" in r]  # not on the untrained agent's row
    norms = [r["parameter_norm"] for r in rows if "parameter_norm" in r]
    out = {
        "env": config.env, "method": config.method, "planner": config.planner, "env_args": config.env_args,
        "seed": config.seed, "population": config.population, "learning_rate": config.learning_rate,
        "lr_decay_iterations": config.lr_decay_iterations, "weight_decay": config.weight_decay,
        "episodes_per_member": config.episodes_per_member, "fitness_shaping": config.fitness_shaping,
        "sigma": config.sigma, "perturbation_rank": config.perturbation_rank,
        "iterations": rows[-1]["iteration"] if rows else 0,
        "training_s": round(rows[-1]["wall_time_s"], 1) if rows else 0.0,
        "median_iteration_s": round(statistics.median(times), 3) if times else None,
        "parameter_norm_at_end": round(norms[-1], 1) if norms else None,
        "curve_iteration_score_wall_s": [[r["iteration"], r["eval_mean_score"], round(r["wall_time_s"], 1)]
                                         for r in evals],
    }
    out.update(population_spread(rows))
    if eval_path is not None:
        out["held_out"] = held_out(eval_path)
    return out


def population_spread(rows: list[dict]) -> dict:
    """How much the members' scores differed: the fraction of iterations in which every member scored the same
    (ES then has no signal: a zero gradient), and the best member score in the first tenth and the rest of the
    run. A population collapsed onto one behaviour reads as a fraction near 1."""
    trained = [r for r in rows if "std_score" in r]
    if not trained:
        return {}
    tenth = max(1, len(trained) // 10)
    return {"all_tied_iterations_fraction": round(sum(r["std_score"] == 0 for r in trained) / len(trained), 3),
            "best_member_score_first_tenth": max(r["max_score"] for r in trained[:tenth]),
            "best_member_score_after": max((r["max_score"] for r in trained[tenth:]), default=None)}


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("runs", nargs="+", metavar="LABEL=RUN_DIR[:EVAL_JSON]")
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--command", required=True, help="the commands that made the runs, for the record")
    parser.add_argument("--machine", default="2 CPU cores, 2 workers, nothing else running",
                        help="where and how the runs ran (e.g. two runs side by side, one core each)")
    args = parser.parse_args(argv)
    runs = {}
    for spec in args.runs:
        label, _, paths = spec.partition("=")
        path, _, eval_path = paths.partition(":")
        if not label or not path:
            parser.error(f"a run must read LABEL=RUN_DIR[:EVAL_JSON], got {spec!r}")
        runs[label] = summary(Path(path), Path(eval_path) if eval_path else None)
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True, text=True).stdout.strip()
    record = {"command": args.command, "summarised_at_commit": commit,
              "machine": args.machine, "runs": runs}
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(record, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
