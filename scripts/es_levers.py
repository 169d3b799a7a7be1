"""An ES setting against the default, paired on the same held-out episodes, into one JSON, and the learning
page's tables from it.

Usage::

    python scripts/es_levers.py compare --out docs/results/es_levers.json --setting common-episodes \
        SETTING_RUN=DEFAULT_RUN ...
    python scripts/es_levers.py page --out docs/results/es_levers.json --page docs/learning.md

``compare``: each pair is a run trained with the setting and the run trained at the default, of the same
environment, seed, method and planner, side by side for the same minutes; both play the same held-out
episodes (``pizero compare``, on the default run's evaluation parameters). A row of ``comparisons`` keeps
``paired_difference`` (the setting's mean score minus the default's), its 95% BCa interval, both scores and
iteration counts, the setting run's training ``minutes`` and both runs' names in the ``runs`` map. Rows
already in the file are kept and not measured again: a batch resumes where it stopped.
``page`` writes the tables between the page's generated markers (a block named after an environment holds
that environment's rows, for its own page).
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
    trained,
    write,
)

from pizero_ray.evaluation.runs import compare_runs  # noqa: E402
from pizero_ray.storage import run_dir  # noqa: E402

BEGIN = "<!-- generated from docs/results/es_levers.json: {name} -->"


def run_record(path: Path) -> dict:
    """What a run was: its environment, seed, method, planner, the ES settings this page compares, and how long
    it trained."""
    config, rows = run_dir.read_config(path), run_dir.read_metrics(path)
    return {"env": config.env, "seed": config.seed, "method": config.method, "planner": config.planner,
            "fitness_shaping": config.fitness_shaping, "common_episodes": config.common_episodes,
            "episodes_per_member": config.episodes_per_member, **trained(rows)}


def _key(row: dict) -> tuple:
    """A comparison's identity, in the table's order."""
    return row["env"], row["method"], row["setting"], row["minutes"], row["seed"]


def compare(out: Path, pairs: list[tuple[Path, Path]], setting: str, episodes: int, seed: int,
            progress=print) -> dict:
    """Each (setting run, default run) pair played on the same episodes, measured once: rows of ``comparisons``."""
    data = load(out, ("comparisons",))
    for with_setting, default in pairs:
        record, other = run_record(with_setting), run_record(default)
        same = ("env", "seed", "method", "planner")
        if any(record[name] != other[name] for name in same):
            raise ValueError(f"{default} is not a run of {with_setting}'s environment, seed, method and planner")
        setting_key, default_key = run_key(with_setting, record), run_key(default, other)
        if setting_key == default_key:
            raise ValueError(f"{with_setting} and {default} would both be named {setting_key}: keep each batch "
                             "in its own folder")
        row = {"env": record["env"], "seed": record["seed"], "method": record["method"], "setting": setting,
               "minutes": budget_minutes(record)}
        if measured(data["comparisons"], _key, row, "setting_run", setting_key):
            continue
        remember_run(data["runs"], setting_key, with_setting, dict(record, setting=setting))
        remember_run(data["runs"], default_key, default, dict(other, setting="default"))
        progress(f"es_levers: {with_setting} against {default}")
        env_args = dict(run_dir.read_schedule(default).get("eval_env_args") or ())
        found = compare_runs(with_setting, default, episodes, seed, env_args=env_args)
        row.update(paired_fields(found, ("setting", "default"), (record, other), (setting_key, default_key),
                               episodes, seed))
        data["comparisons"].append(row)
        data["comparisons"].sort(key=_key)
        write(out, data)
    return data


# ------------------------------------------------------------------ the page's tables

def _groups(data: dict):
    """Each (environment, method, setting, minutes) with its rows, in the table's order."""
    rows = sorted(data["comparisons"], key=_key)
    return ((group, list(found)) for group, found in itertools.groupby(rows, key=lambda row: _key(row)[:4]))


def comparison_table(data: dict, decimals: dict) -> list[str]:
    """Per environment, method, setting and minutes: each seed's paired difference, then their mean (bold) and how
    many seeds' intervals lie above zero (the setting ahead) and below it."""
    lines = ["| environment | method | setting | minutes | seed | with the setting | default | setting minus default, "
             "95% BCa | iterations (setting, default) |", "|---|---|---|---|---|---|---|---|---|"]
    for (env, method, setting, minutes), rows in _groups(data):
        places = decimals.get(env, 3)
        for row in rows:
            lines.append(f"| {env} | {method} | {setting} | {minutes} | {row['seed']} | "
                         f"{row['setting_score']:.{places}f} | {row['default_score']:.{places}f} | "
                         f"{interval(row, places)} | {row['setting_iterations']:,}, {row['default_iterations']:,} |")
        mean, above, below = seeds_clear_of_zero(rows)
        lines.append(f"| {env} | {method} | {setting} | {minutes} | mean of {len(rows)} | | | "
                     f"**{mean:+.{places}f}**: {above} above zero, {below} below | |")
    return lines


def summary_lines(data: dict, decimals: dict) -> list[str]:
    """One line per environment, method, setting and minutes: the setting's mean paired difference from the
    default, and how many seeds' intervals lie clear of zero."""
    lines = []
    for (env, method, setting, minutes), rows in _groups(data):
        lines.append(f"- **{env}**, {method}, `{setting}` for {minutes} minutes, minus the default: "
                     f"{mean_and_count(rows, decimals.get(env, 3))}.")
    return lines


TABLES = {"comparisons": comparison_table, "summary": summary_lines}


def _one_environment(env: str):
    """The comparison table of one environment's rows, for its own page."""
    return lambda data, decimals: comparison_table(
        {"comparisons": [row for row in data["comparisons"] if row["env"] == env]}, decimals)


def render_page(text: str, data: dict, decimals: dict | None = None) -> str:
    """``text`` with each generated block replaced by its table from ``data``: ``summary`` and ``comparisons``
    for every environment, or a block named after one environment for its rows alone."""
    tables = dict(TABLES) | {env: _one_environment(env) for env in {row["env"] for row in data["comparisons"]}}
    return render_blocks(text, BEGIN, tables, data, env_decimals() if decimals is None else decimals)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    command = sub.add_parser("compare")
    command.add_argument("pairs", nargs="+", metavar="SETTING_RUN=DEFAULT_RUN")
    command.add_argument("--out", type=Path, required=True)
    command.add_argument("--setting", required=True, help="a short name for the setting the first runs changed")
    command.add_argument("--episodes", type=int, default=1000)
    command.add_argument("--seed", type=int, default=0)
    page = sub.add_parser("page")
    page.add_argument("--out", type=Path, required=True)
    page.add_argument("--page", type=Path, required=True)
    args = parser.parse_args(argv)
    if args.command == "compare":
        try:
            pairs = parse_pairs(args.pairs)
        except ValueError as error:
            parser.error(str(error))
        compare(args.out, pairs, args.setting, args.episodes, args.seed,
                progress=lambda text: print(text, file=sys.stderr, flush=True))
    else:
        args.page.write_text(render_page(args.page.read_text(), load(args.out, ("comparisons",))))
    return 0


if __name__ == "__main__":
    sys.exit(main())
