"""What each trained agent's plan and lookahead are worth, into one JSON, and docs/planning.md's tables from it.

Usage::

    python scripts/plan_ablations.py ablate --out docs/results/planning.json --config default --default \
        [--ablations shuffled,zeroed,simulations=1,simulations=30] [--episodes 1000] RUN_DIR ...
    python scripts/plan_ablations.py verdict --out docs/results/planning.json --config default --default \
        --budget equal_time PIZERO_RUN=PLANNER_FREE_RUN ...
    python scripts/plan_ablations.py page --out docs/results/planning.json --page docs/planning.md

``ablate``: for each run dir and ablation, one row of the JSON's ``ablations``
list: the same parameters on the same held-out episodes (``--seed``, on the
run's own evaluation parameters from its evaluation.json: Sokoban's valid
levels, 2048's horizon), with the plan shuffled between episodes or zeroed
(``pizero eval --plan``) or the search budget changed (``pizero compare
--simulations-a``). ``paired_difference`` is the ablated agent's mean score
minus the intact agent's, with its 95% BCa interval; ``share_changed`` the
share of episodes whose score changed, ``share_actions_changed`` (plan
ablations) the share of the intact agent's actions the ablation changes.
``verdict``: PiZero against the planner-free agent of the same environment and
seed on the same episodes (``pizero compare``), a row of ``verdicts``:
``paired_difference`` is PiZero minus the planner-free agent. The ``runs`` map
keeps each run's iterations, training minutes and intact score. Rows already in
the file are kept and not measured again: a batch resumes where it stopped.
``page`` writes the tables between docs/planning.md's generated markers.
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


def _load(out: Path) -> dict:
    data = json.loads(out.read_text()) if out.exists() else {}
    for name, empty in (("ablations", []), ("verdicts", []), ("runs", {})):
        data.setdefault(name, empty)
    return data


def update(out: Path, paths: list[Path], config_name: str, default: bool, ablations: list[str], episodes: int,
           seed: int, progress=print) -> dict:
    """Measures every (run, ablation) not yet in ``out`` and rewrites it after each: a resumable batch."""
    data = _load(out)
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


def _verdict_key(row: dict) -> tuple:
    return row["env"], row["seed"], row["config"], row["budget"]


def judge(out: Path, pairs: list[tuple[Path, Path]], config_name: str, default: bool, budget: str, episodes: int,
          seed: int, progress=print) -> dict:
    """PiZero against the planner-free run of the same environment and seed, paired on the same episodes: rows
    of ``verdicts`` (PiZero minus the planner-free agent), each measured once."""
    data = _load(out)
    for pizero, planner_free in pairs:
        record, other = run_record(pizero), run_record(planner_free)
        if (record["env"], record["seed"]) != (other["env"], other["seed"]) or other["planner"] != "none":
            raise ValueError(f"{planner_free} is not the planner-free run of {pizero}'s environment and seed")
        row = {"env": record["env"], "seed": record["seed"], "config": config_name, "budget": budget}
        if _verdict_key(row) in {_verdict_key(done) for done in data["verdicts"]}:
            continue
        progress(f"plan_ablations: {pizero} against {planner_free} ({budget})")
        env_args = dict(run_dir.read_schedule(pizero).get("eval_env_args") or ())
        found = compare_runs(pizero, planner_free, episodes, seed, env_args=env_args)
        data["runs"][f"{record['env']}/{config_name}/seed{record['seed']}"] = record
        data["runs"][f"{record['env']}/planner-free/seed{record['seed']}"] = other
        row.update(paired_difference=found["mean_difference"], ci95=found["ci95"], pizero_score=found["mean_score_a"],
                   planner_free_score=found["mean_score_b"], pizero_iterations=record["iterations"],
                   planner_free_iterations=other["iterations"], default=default, episodes=episodes,
                   episode_seed=seed)
        data["verdicts"].append(row)
        data["verdicts"].sort(key=_verdict_key)
        _write(out, data)
    return data


def _write(out: Path, data: dict) -> None:
    tmp = out.with_name(out.name + ".tmp")
    tmp.write_text(json.dumps(data, indent=1, sort_keys=True) + "\n")
    tmp.replace(out)


# ------------------------------------------------------------------ the page's tables

BEGIN, END = "<!-- generated from docs/results/planning.json: {name} -->", "<!-- end generated -->"


def _interval(row: dict) -> str:
    low, high = row["ci95"]
    return f"{row['paired_difference']:+.3f} ({low:+.3f}, {high:+.3f})"


def _column_order(ablation: str) -> tuple:
    """The plan ablations first (shuffled, zeroed), then the budgets by size."""
    search = parse_ablation(ablation)
    return (0, PLAN_ABLATIONS.index(search.plan)) if search.plan else (1, search.simulations)


def ablation_table(data: dict) -> list[str]:
    """Per environment and configuration: each ablation's paired difference on every seed, and their mean."""
    ablations = sorted({row["ablation"] for row in data["ablations"]}, key=_column_order)
    lines = ["| environment | configuration | seeds | " + " | ".join(ablations) + " |",
             "|---|---|---|" + "---|" * len(ablations)]
    groups = sorted({(row["env"], row["config"]) for row in data["ablations"]})
    for env, config in groups:
        rows = [row for row in data["ablations"] if (row["env"], row["config"]) == (env, config)]
        seeds = sorted({row["seed"] for row in rows})
        cells = []
        for ablation in ablations:
            found = [row for row in rows if row["ablation"] == ablation]
            if not found:
                cells.append("")
                continue
            mean = sum(row["paired_difference"] for row in found) / len(found)
            each = "; ".join(f"seed {row['seed']}: {_interval(row)}" for row in found)
            cells.append(f"**{mean:+.3f}** ({each})")
        default = " (default)" if any(row["default"] for row in rows) else ""
        lines.append(f"| {env} | {config}{default} | {len(seeds)} | " + " | ".join(cells) + " |")
    return lines


def runs_table(data: dict) -> list[str]:
    lines = ["| run | iterations | training minutes | decoder reads |", "|---|---|---|---|"]
    for name, record in sorted(data["runs"].items()):
        reads = ",".join(record["decoder_inputs"]) if record["planner"] != "none" else "state (no planner)"
        lines.append(f"| {name} | {record['iterations']:,} | {record['training_minutes']:.1f} | {reads} |")
    return lines


def verdict_table(data: dict) -> list[str]:
    lines = ["| environment | configuration | budget | seed | PiZero | planner-free | PiZero minus planner-free, "
             "95% BCa | iterations (PiZero, planner-free) |", "|---|---|---|---|---|---|---|---|"]
    for row in data["verdicts"]:
        lines.append(f"| {row['env']} | {row['config']} | {row['budget'].replace('_', ' ')} | {row['seed']} | "
                     f"{row['pizero_score']:.3f} | {row['planner_free_score']:.3f} | {_interval(row)} | "
                     f"{row['pizero_iterations']:,}, {row['planner_free_iterations']:,} |")
    return lines


TABLES = {"ablations": ablation_table, "verdicts": verdict_table, "runs": runs_table}


def render_page(text: str, data: dict) -> str:
    """``text`` with each generated block (between its markers) replaced by its table from ``data``."""
    for name, table in TABLES.items():
        begin = BEGIN.format(name=name)
        if begin not in text:
            continue
        head, rest = text.split(begin, 1)
        _, tail = rest.split(END, 1)
        text = head + begin + "\n" + "\n".join(table(data)) + "\n" + END + tail
    return text


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    for name in ("ablate", "verdict"):
        command = sub.add_parser(name)
        command.add_argument("runs", nargs="+")
        command.add_argument("--out", type=Path, required=True)
        command.add_argument("--config", required=True, help="a short name for the runs' configuration")
        command.add_argument("--default", action="store_true", help="the configuration the environment ships with")
        command.add_argument("--episodes", type=int, default=1000)
        command.add_argument("--seed", type=int, default=0)
        if name == "ablate":
            command.add_argument("--ablations", default=",".join(DEFAULT_ABLATIONS))
        else:
            command.add_argument("--budget", choices=("equal_time", "equal_iterations"), required=True)
    page = sub.add_parser("page")
    page.add_argument("--out", type=Path, required=True)
    page.add_argument("--page", type=Path, required=True)
    args = parser.parse_args(argv)
    say = lambda text: print(text, file=sys.stderr, flush=True)  # noqa: E731
    if args.command == "ablate":
        update(args.out, [Path(path).absolute() for path in args.runs], args.config, args.default,
               args.ablations.split(","), args.episodes, args.seed, progress=say)
    elif args.command == "verdict":
        pairs = [tuple(Path(side).absolute() for side in pair.split("=", 1)) for pair in args.runs]
        judge(args.out, pairs, args.config, args.default, args.budget, args.episodes, args.seed, progress=say)
    else:
        args.page.write_text(render_page(args.page.read_text(), _load(args.out)))
    return 0


if __name__ == "__main__":
    sys.exit(main())
