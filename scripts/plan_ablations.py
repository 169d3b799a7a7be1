"""What each trained agent's plan and lookahead are worth, into one JSON, and docs/planning.md's tables from it.

Usage::

    python scripts/plan_ablations.py ablate --out docs/results/planning.json --config default --default \
        [--ablations shuffled,zeroed,simulations=1,simulations=30] [--episodes 1000] RUN_DIR ...
    python scripts/plan_ablations.py verdict --out docs/results/planning.json --config default --default \
        --budget equal_time|equal_iterations [--minutes M] PIZERO_RUN=PLANNER_FREE_RUN ...
    python scripts/plan_ablations.py choose --out docs/results/planning.json --config NAME --against NAME \
        CANDIDATE_RUN=INCUMBENT_RUN ...
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
``paired_difference`` is PiZero minus the planner-free agent; with ``--budget
equal_iterations --minutes M`` its PiZero runs were trained (``pizero train
--iterations N``) to the iteration counts of M-minute runs already in the
file, and their rows stand under M minutes (``iterations_of`` names that
run). ``choose``: one
PiZero configuration against another (the default it would replace), both
trained the same minutes on the same seed, a row of ``choices``:
``paired_difference`` is ``config`` minus ``against``. Every row says
how many ``minutes`` its PiZero run trained, so a configuration's 10-minute
and 30-minute runs stay apart. The ``runs`` map
keeps each run's iterations, training minutes and intact score. Rows already in
the file are kept and not measured again: a batch resumes where it stopped.
``page`` writes the tables between docs/planning.md's generated markers.
"""

from __future__ import annotations

import argparse
import itertools
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from paired_results import (  # noqa: E402
    budget_minutes,
    env_decimals,
    interval,
    load,
    mean_and_count,
    measured,
    paired_fields,
    parse_pairs,
    remember_run,
    render_blocks,
    run_key,
    seeds_clear_of_zero,
    signed,
    trained,
    write,
)

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
    """What a row's run was: its environment, seed, iterations and training minutes, and what shuffling its plan
    cost at its last learning-curve evaluation (``None`` without a planner or an evaluation)."""
    config, rows = run_dir.read_config(path), run_dir.read_metrics(path)
    evaluations = [row for row in rows if "eval_plan_shuffled_score" in row]
    last = evaluations[-1] if evaluations else None
    return {"env": config.env, "seed": config.seed, "method": config.method, "planner": config.planner,
            "num_simulations": config.num_simulations, "decoder_inputs": list(config.decoder_inputs),
            **trained(rows),
            "last_plan_shuffled_difference":
                last["eval_plan_shuffled_score"] - last["eval_mean_score"] if last else None,
            "last_plan_actions_changed": last["eval_plan_actions_changed"] if last else None}


def _key(row: dict) -> tuple:
    return row["env"], row["seed"], row["config"], row["minutes"], row["ablation"]


def _load(out: Path) -> dict:
    return load(out, ("ablations", "verdicts", "choices"))


def update(out: Path, paths: list[Path], config_name: str, default: bool, ablations: list[str], episodes: int,
           seed: int, progress=print) -> dict:
    """Measures every (run, ablation) not yet in ``out`` and rewrites it after each: a resumable batch."""
    data = _load(out)
    for ablation in ablations:
        parse_ablation(ablation)  # every name checked before the first measurement
    for path in paths:
        record = run_record(path)
        key = run_key(path, record)
        remember_run(data["runs"], key, path, dict(record, config=config_name))
        for ablation in ablations:
            row = {"env": record["env"], "seed": record["seed"], "config": config_name,
                   "minutes": budget_minutes(record), "ablation": ablation}
            if measured(data["ablations"], _key, row, "run", key):
                continue
            progress(f"plan_ablations: {path} {ablation}")
            row.update(measure(path, ablation, episodes, seed), default=default, episodes=episodes,
                       episode_seed=seed, run=key)
            data["ablations"].append(row)
            data["ablations"].sort(key=_key)
            write(out, data)
    write(out, data)
    return data


def _verdict_key(row: dict) -> tuple:
    """A verdict's identity, in the table's order: each environment, configuration and budget's seeds together."""
    return row["env"], row["config"], row["minutes"], row["budget"], row["seed"]


def iterations_of(data: dict, record: dict, config_name: str, minutes: int, path: Path, own: str) -> str:
    """The name of the ``minutes``-minute run whose iteration count ``record``'s run was trained to: the one run
    of the ``runs`` map with its environment, seed, configuration and iterations that trained that budget. An
    equal-iterations verdict needs only the count, so a run trained with ``--iterations N`` can stand for a
    ``--minutes`` run that stopped at N. It need not be that run's agent (retrained on another machine, some
    agents were and some were not), so its row names its own run."""
    found = [key for key, known in data["runs"].items()
             if key != own and (known["env"], known["seed"], known.get("config"), known["iterations"]) == (
                 record["env"], record["seed"], config_name, record["iterations"])
             and budget_minutes(known) == minutes]
    if len(found) != 1:
        raise ValueError(f"{path} has the iterations of no {minutes}-minute {config_name} run of {record['env']} "
                         f"seed {record['seed']}: it made {record['iterations']}")
    return found[0]


def judge(out: Path, pairs: list[tuple[Path, Path]], config_name: str, default: bool, budget: str, episodes: int,
          seed: int, progress=print, minutes: int | None = None) -> dict:
    """PiZero against the planner-free run of the same environment and seed, paired on the same episodes: rows
    of ``verdicts`` (PiZero minus the planner-free agent), each measured once. With ``minutes`` (equal
    iterations only), each PiZero run was trained to the iteration count of a run of that budget already in
    the file (``iterations_of``), and its row stands under that budget, naming that run in ``iterations_of``."""
    if minutes is not None and budget != "equal_iterations":
        raise ValueError(f"--minutes stands an iteration-bound run under a budget: equal iterations only, not {budget}")
    data = _load(out)
    for pizero, planner_free in pairs:
        record, other = run_record(pizero), run_record(planner_free)
        if (record["env"], record["seed"]) != (other["env"], other["seed"]) or other["planner"] != "none":
            raise ValueError(f"{planner_free} is not the planner-free run of {pizero}'s environment and seed")
        row = {"env": record["env"], "seed": record["seed"], "config": config_name,
               "minutes": budget_minutes(record) if minutes is None else minutes, "budget": budget}
        pizero_key, planner_free_key = run_key(pizero, record), run_key(planner_free, other)
        if measured(data["verdicts"], _verdict_key, row, "pizero_run", pizero_key):
            continue
        if minutes is not None:
            row["iterations_of"] = iterations_of(data, record, config_name, minutes, pizero, pizero_key)
        remember_run(data["runs"], pizero_key, pizero, dict(record, config=config_name))
        remember_run(data["runs"], planner_free_key, planner_free, dict(other, config="planner-free"))
        progress(f"plan_ablations: {pizero} against {planner_free} ({budget})")
        env_args = dict(run_dir.read_schedule(pizero).get("eval_env_args") or ())
        found = compare_runs(pizero, planner_free, episodes, seed, env_args=env_args)
        row.update(paired_fields(found, ("pizero", "planner_free"), (record, other), (pizero_key, planner_free_key),
                                 episodes, seed),
                   pizero_plan_shuffled_difference=record["last_plan_shuffled_difference"], default=default)
        data["verdicts"].append(row)
        data["verdicts"].sort(key=_verdict_key)
        write(out, data)
    return data


def _choice_key(row: dict) -> tuple:
    return row["env"], row["config"], row["against"], row["minutes"], row["seed"]


def choose(out: Path, pairs: list[tuple[Path, Path]], config_name: str, against: str, episodes: int, seed: int,
           progress=print) -> dict:
    """A PiZero configuration against another, of the same environment and seed and trained the same minutes
    (equal time), paired on the same episodes: rows of ``choices`` (``config`` minus ``against``), each measured
    once. How a configuration earns the default."""
    data = _load(out)
    for candidate, incumbent in pairs:
        record, other = run_record(candidate), run_record(incumbent)
        if (record["env"], record["seed"], budget_minutes(record)) != (
                other["env"], other["seed"], budget_minutes(other)) or "none" in (record["planner"], other["planner"]):
            raise ValueError(f"{incumbent} is not a PiZero run of {candidate}'s environment and seed trained as many "
                             "minutes")
        row = {"env": record["env"], "seed": record["seed"], "config": config_name, "against": against,
               "minutes": budget_minutes(record)}
        candidate_key, incumbent_key = run_key(candidate, record), run_key(incumbent, other)
        if measured(data["choices"], _choice_key, row, "config_run", candidate_key):
            continue
        remember_run(data["runs"], candidate_key, candidate, dict(record, config=config_name))
        remember_run(data["runs"], incumbent_key, incumbent, dict(other, config=against))
        progress(f"plan_ablations: {candidate} against {incumbent}")
        env_args = dict(run_dir.read_schedule(candidate).get("eval_env_args") or ())
        found = compare_runs(candidate, incumbent, episodes, seed, env_args=env_args)
        row.update(paired_fields(found, ("config", "against"), (record, other), (candidate_key, incumbent_key),
                                 episodes, seed))
        data["choices"].append(row)
        data["choices"].sort(key=_choice_key)
        write(out, data)
    return data


# ------------------------------------------------------------------ the page's tables

BEGIN = "<!-- generated from docs/results/planning.json: {name} -->"


def _column_order(ablation: str) -> tuple:
    """The plan ablations first (shuffled, zeroed), then the budgets by size."""
    search = parse_ablation(ablation)
    return (0, PLAN_ABLATIONS.index(search.plan)) if search.plan else (1, search.simulations)


def ablation_table(data: dict, decimals: dict) -> list[str]:
    """Per environment and configuration: each seed's paired difference for every ablation, with its interval,
    then their mean over the seeds (bold), and the share of actions the shuffled plan changes."""
    ablations = sorted({row["ablation"] for row in data["ablations"]}, key=_column_order)
    lines = ["| environment | configuration | minutes | seed | intact score | " + " | ".join(ablations)
             + " | actions the shuffled plan changes |", "|---|---|---|---|---|" + "---|" * (len(ablations) + 1)]
    groups = {(row["env"], not row["default"], row["config"], row["minutes"]) for row in data["ablations"]}
    for env, _, config, minutes in sorted(groups):  # each environment's default first
        rows = [row for row in data["ablations"] if (row["env"], row["config"], row["minutes"]) == (
            env, config, minutes)]
        places = decimals.get(env, 3)
        shipped = any(row["default"] for row in rows) and config != "default"
        label = f"{config} (the default)" if shipped else config
        seeds = sorted({row["seed"] for row in rows})
        for seed in seeds:
            found = {row["ablation"]: row for row in rows if row["seed"] == seed}
            intact = next(iter(found.values()))["intact_mean_score"]
            shuffled = found.get("shuffled", {}).get("share_actions_changed")
            cells = [interval(found[a], places) if a in found else "" for a in ablations]
            lines.append(f"| {env} | {label} | {minutes} | {seed} | {intact:.{places}f} | " + " | ".join(cells)
                         + f" | {'' if shuffled is None else f'{shuffled:.1%}'} |")
        means = []
        for ablation in ablations:
            found = [row for row in rows if row["ablation"] == ablation]
            if not found:
                means.append("")
                continue
            mean, _, below = seeds_clear_of_zero(found)
            means.append(f"**{mean:+.{places}f}**, {below} of {len(found)} below zero")
        lines.append(f"| {env} | {label} | {minutes} | mean of {len(seeds)} | | " + " | ".join(means) + " | |")
    return lines


def runs_table(data: dict, decimals: dict) -> list[str]:
    lines = ["| run | configuration | iterations | training minutes | decoder reads | plan shuffled at the last "
             "training evaluation (200 episodes) |", "|---|---|---|---|---|---|"]
    for name, record in sorted(data["runs"].items()):
        reads = ",".join(record["decoder_inputs"]) if record["planner"] != "none" else "state (no planner)"
        lines.append(f"| {name} | {record.get('config', '')} | {record['iterations']:,} | "
                     f"{record['training_minutes']:.1f} | {reads} | "
                     f"{signed(record.get('last_plan_shuffled_difference'), decimals.get(record['env'], 3))} |")
    return lines


def verdict_table(data: dict, decimals: dict) -> list[str]:
    lines = ["| environment | configuration | minutes | budget | seed | PiZero | planner-free | PiZero minus "
             "planner-free, 95% BCa | iterations (PiZero, planner-free) | PiZero's plan shuffled (last training "
             "evaluation) |", "|---|---|---|---|---|---|---|---|---|---|"]
    verdicts = sorted(data["verdicts"], key=lambda row: (row["env"], not row["default"], row["config"],
                                                         row["minutes"], row["budget"] != "equal_time", row["seed"]))
    for (env, config, minutes, budget), group in itertools.groupby(verdicts, key=lambda row: _verdict_key(row)[:4]):
        rows, places = list(group), decimals.get(env, 3)
        for row in rows:
            lines.append(f"| {env} | {config} | {minutes} | {budget.replace('_', ' ')} | {row['seed']} | "
                         f"{row['pizero_score']:.{places}f} | {row['planner_free_score']:.{places}f} | "
                         f"{interval(row, places)} | {row['pizero_iterations']:,}, "
                         f"{row['planner_free_iterations']:,} | "
                         f"{signed(row.get('pizero_plan_shuffled_difference'), places)} |")
        mean, above, below = seeds_clear_of_zero(rows)  # planning pays above zero, costs below
        lines.append(f"| {env} | {config} | {minutes} | {budget.replace('_', ' ')} | mean of {len(rows)} | | | "
                     f"**{mean:+.{places}f}**: {above} above zero, {below} below | | |")
    return lines


def choice_table(data: dict, decimals: dict) -> list[str]:
    """Each configuration against the one it was measured to replace, seed by seed, then the mean."""
    lines = ["| environment | configuration | against | minutes | seed | configuration's score | against's score | "
             "difference, 95% BCa | iterations (configuration, against) |", "|---|---|---|---|---|---|---|---|---|"]
    for (env, config, against, minutes), group in itertools.groupby(sorted(data["choices"], key=_choice_key),
                                                                      key=lambda row: _choice_key(row)[:4]):
        rows, places = list(group), decimals.get(env, 3)
        for row in rows:
            lines.append(f"| {env} | {config} | {against} | {minutes} | {row['seed']} | "
                         f"{row['config_score']:.{places}f} | {row['against_score']:.{places}f} | "
                         f"{interval(row, places)} | {row['config_iterations']:,}, {row['against_iterations']:,} |")
        mean, above, below = seeds_clear_of_zero(rows)
        lines.append(f"| {env} | {config} | {against} | {minutes} | mean of {len(rows)} | | | "
                     f"**{mean:+.{places}f}**: {above} above zero, {below} below | |")
    return lines


def summary_lines(data: dict, decimals: dict) -> list[str]:
    """One line per environment, configuration and training minutes (the default first): what shuffling the
    plan and searching with 1 simulation cost (mean over seeds, and how many seeds' intervals lie clear of zero),
    and each budget's verdict against the planner-free agent."""
    lines = []
    configs = {(row["env"], row["config"], row["minutes"], row["default"])
               for row in data["ablations"] + data["verdicts"]}
    for env, config, minutes, default in sorted(configs, key=lambda found: (found[0], not found[3], *found[1:3])):
        places = decimals.get(env, 3)
        rows = [row for row in data["ablations"] if (row["env"], row["config"], row["minutes"]) == (
            env, config, minutes)]
        parts = [f"{name} {mean_and_count(found, places)}"
                 for ablation, name in (("shuffled", "plan shuffled"), ("simulations=1", "1 simulation"))
                 if (found := [row for row in rows if row["ablation"] == ablation])]
        for budget in ("equal_time", "equal_iterations"):
            found = [row for row in data["verdicts"] if (row["env"], row["config"], row["minutes"], row["budget"]) == (
                env, config, minutes, budget)]
            if found:
                parts.append(f"PiZero minus the planner-free agent at {budget.replace('_', ' ')} "
                             f"{mean_and_count(found, places)}")
        name = "at the default" if config == "default" else f"`{config}`{', the default' if default else ''}"
        name += f", {minutes} minutes"
        lines.append(f"- **{env}** {name}: " + "; ".join(parts) + ".")
    return lines


TABLES = {"ablations": ablation_table, "verdicts": verdict_table, "choices": choice_table, "runs": runs_table,
          "summary": summary_lines}


def render_page(text: str, data: dict, decimals: dict | None = None) -> str:
    """``text`` with each generated block (between its markers) replaced by its table from ``data``; scores at
    each environment's ``decimals`` (``env_decimals()`` when not given)."""
    return render_blocks(text, BEGIN, TABLES, data, env_decimals() if decimals is None else decimals)


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
            command.add_argument("--minutes", type=int,
                                 help="equal iterations: the PiZero runs were trained to the iteration counts of runs "
                                      "of this many minutes already in the file; their rows stand under that budget")
    choice = sub.add_parser("choose")
    choice.add_argument("runs", nargs="+", metavar="CANDIDATE_RUN=INCUMBENT_RUN")
    choice.add_argument("--out", type=Path, required=True)
    choice.add_argument("--config", required=True, help="a short name for the candidates' configuration")
    choice.add_argument("--against", required=True, help="a short name for the incumbents' configuration")
    choice.add_argument("--episodes", type=int, default=1000)
    choice.add_argument("--seed", type=int, default=0)
    page = sub.add_parser("page")
    page.add_argument("--out", type=Path, required=True)
    page.add_argument("--page", type=Path, required=True)
    args = parser.parse_args(argv)
    say = lambda text: print(text, file=sys.stderr, flush=True)  # noqa: E731
    if args.command == "page":
        args.page.write_text(render_page(args.page.read_text(), _load(args.out)))
        return 0
    try:  # a refused run or pair is one line, before or between measurements (each row is written once measured)
        if args.command == "ablate":
            update(args.out, [Path(path).absolute() for path in args.runs], args.config, args.default,
                   args.ablations.split(","), args.episodes, args.seed, progress=say)
        elif args.command == "verdict":
            judge(args.out, parse_pairs(args.runs), args.config, args.default, args.budget, args.episodes,
                  args.seed, progress=say, minutes=args.minutes)
        else:
            choose(args.out, parse_pairs(args.runs), args.config, args.against, args.episodes, args.seed,
                   progress=say)
    except ValueError as error:
        parser.error(str(error))
    return 0


if __name__ == "__main__":
    sys.exit(main())
