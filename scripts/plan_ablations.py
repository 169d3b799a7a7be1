"""What each trained agent's plan and lookahead are worth, into one JSON for docs/planning.md.

Usage::

    python scripts/plan_ablations.py --out docs/results/planning.json --config default --default \
        [--ablations shuffled,zeroed,simulations=1,simulations=30] [--episodes 1000] RUN_DIR ...

For each run dir and ablation, one row of the JSON's ``ablations`` list: the
same parameters on the same held-out episodes (``--seed``, on the run's own
evaluation parameters from its evaluation.json: Sokoban's valid levels,
2048's horizon), with the plan shuffled between episodes or zeroed
(``pizero eval --plan``) or the search budget changed (``pizero compare
--simulations-a``). ``paired_difference`` is the ablated agent's mean score
minus the intact agent's, with its 95% BCa interval; ``share_changed`` the
share of episodes whose score changed, ``share_actions_changed`` (plan
ablations) the share of the intact agent's actions the ablation changes.
The ``runs`` map keeps each run's iterations, training minutes and intact
score. Rows already in the file are kept and not measured again: the batch
resumes where it stopped.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pizero_ray.config import PLAN_ABLATIONS  # noqa: E402
from pizero_ray.evaluation.runs import Search, compare_runs, evaluate_run  # noqa: E402
from pizero_ray.storage import run_dir  # noqa: E402

DEFAULT_ABLATIONS = ("shuffled", "zeroed", "simulations=1", "simulations=30")


def parse_ablation(text: str) -> Search:
    """"shuffled", "zeroed" or "simulations=N" as the search the ablated side plays with."""
    if text in PLAN_ABLATIONS:
        return Search(plan=text)
    name, _, value = text.partition("=")
    if name == "simulations" and value.isdigit() and int(value) > 0:
        return Search(simulations=int(value))
    raise ValueError(f"unknown ablation {text!r}: shuffled, zeroed or simulations=N")


def measure(path: Path, ablation: str, episodes: int, seed: int) -> dict:
    """One ablation of one run: the paired difference (ablated minus intact) on the run's evaluation episodes."""
    env_args = dict(run_dir.read_schedule(path).get("eval_env_args") or ())
    search = parse_ablation(ablation)
    if search.plan is not None:
        found = evaluate_run(path, episodes, seed, env_args, plan=search.plan)
        return {"paired_difference": found["plan_difference"], "ci95": found["plan_difference_ci95"],
                "share_changed": 1.0 - found["share_episodes_unchanged"],
                "share_actions_changed": found["share_actions_changed"],
                "intact_mean_score": found["intact_mean_score"]}
    found = compare_runs(path, path, episodes, seed, search_a=search, env_args=env_args)
    return {"paired_difference": found["mean_difference"], "ci95": found["ci95"],
            "share_changed": 1.0 - found["share_tied"], "share_actions_changed": None,
            "intact_mean_score": found["mean_score_b"]}


def run_record(path: Path) -> dict:
    """What a row's run was: its environment, seed, iterations and training minutes."""
    config, rows = run_dir.read_config(path), run_dir.read_metrics(path)
    return {"env": config.env, "seed": config.seed, "method": config.method, "planner": config.planner,
            "num_simulations": config.num_simulations, "decoder_inputs": list(config.decoder_inputs),
            "iterations": rows[-1]["iteration"] if rows else 0,
            "training_minutes": round(rows[-1]["wall_time_s"] / 60.0, 2) if rows else 0.0}


def _key(row: dict) -> tuple:
    return row["env"], row["seed"], row["config"], row["ablation"]


def update(out: Path, paths: list[Path], config_name: str, default: bool, ablations: list[str], episodes: int,
           seed: int, progress=print) -> dict:
    """Measures every (run, ablation) not yet in ``out`` and rewrites it after each: a resumable batch."""
    data = json.loads(out.read_text()) if out.exists() else {}
    data.setdefault("ablations", [])
    data.setdefault("verdicts", [])
    data.setdefault("runs", {})
    for ablation in ablations:
        parse_ablation(ablation)  # every name checked before the first measurement
    for path in paths:
        record = run_record(path)
        data["runs"][f"{record['env']}/{config_name}/seed{record['seed']}"] = record
        done = {_key(row) for row in data["ablations"]}
        for ablation in ablations:
            row = {"env": record["env"], "seed": record["seed"], "config": config_name, "ablation": ablation}
            if _key(row) in done:
                continue
            progress(f"plan_ablations: {path} {ablation}")
            row.update(measure(path, ablation, episodes, seed), default=default, episodes=episodes,
                       episode_seed=seed)
            data["ablations"].append(row)
            data["ablations"].sort(key=_key)
            _write(out, data)
    _write(out, data)
    return data


def _write(out: Path, data: dict) -> None:
    tmp = out.with_name(out.name + ".tmp")
    tmp.write_text(json.dumps(data, indent=1, sort_keys=True) + "\n")
    tmp.replace(out)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("run_dirs", nargs="+", type=Path)
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--config", required=True, help="a short name for the runs' configuration")
    parser.add_argument("--default", action="store_true", help="the configuration the environment ships with")
    parser.add_argument("--ablations", default=",".join(DEFAULT_ABLATIONS))
    parser.add_argument("--episodes", type=int, default=1000)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args(argv)
    update(args.out, [path.absolute() for path in args.run_dirs], args.config, args.default,
           args.ablations.split(","), args.episodes, args.seed,
           progress=lambda text: print(text, file=sys.stderr, flush=True))
    return 0


if __name__ == "__main__":
    sys.exit(main())
