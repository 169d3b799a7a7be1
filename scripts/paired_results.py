"""What the docs' paired-result scripts share: a resumable JSON of rows, each run's name and training budget, the
figures' formatting, and the page blocks generated from the JSON.

Used by scripts/plan_ablations.py (PiZero against its own ablations and the planner-free agent) and
scripts/es_levers.py (an ES setting against the default). Not a package module: the scripts put this folder on
``sys.path``.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Callable

SUMMARY = Path(__file__).resolve().parents[1] / "docs" / "results" / "summary.json"
END = "<!-- end generated -->"


def trained(rows: list[dict]) -> dict:
    """How far a run trained, from its metrics rows: its last iteration and its training minutes (0 for none)."""
    return {"iterations": rows[-1]["iteration"] if rows else 0,
            "training_minutes": round(rows[-1]["wall_time_s"] / 60.0, 2) if rows else 0.0}


def budget_minutes(record: dict) -> int:
    """The training budget a run had, in whole minutes: a ``--minutes`` run stops after the iteration under way,
    so it trains its budget and a fraction of an iteration more."""
    return int(record["training_minutes"])


def run_key(path: Path, record: dict) -> str:
    """The ``runs`` map's name for a run: the batch it belongs to, then its place there. In an experiment's
    layout (BATCH/runs/A/B/RUN) that is its folders as named, usually ENV/METHOD/seedS, so two configurations
    of one seed in their own folders keep their own names; a run dir directly in a batch's folder is named by
    its environment, method and seed."""
    parents = path.absolute().parents
    if len(parents) > 3 and parents[2].name == "runs":
        return f"{parents[3].name}/{parents[1].name}/{parents[0].name}/{path.name}"
    return f"{parents[0].name}/{record['env']}/{record['method']}/seed{record['seed']}"


def measured(rows: list[dict], identity: Callable[[dict], tuple], row: dict, run_field: str, run: str) -> bool:
    """Whether ``row`` (its ``identity``) is already among ``rows``, measured on ``run``. A row of that identity
    measured on another run is refused: the page would show one run's figure under the other's name."""
    for done in rows:
        if identity(done) == identity(row):
            if done[run_field] != run:
                raise ValueError(f"{run} would repeat the row {identity(row)} measured on {done[run_field]}: name "
                                 "its configuration otherwise, or train another seed")
            return True
    return False


def remember_run(runs: dict, key: str, path: Path, entry: dict) -> None:
    """Stores ``entry`` under ``key`` in a JSON's ``runs`` map; a different run under a taken name is refused,
    since the rows naming it would then mix two runs' figures."""
    known = runs.get(key)
    if known is not None and any(known[name] != entry[name] for name in known.keys() & entry.keys()):
        raise ValueError(f"{path} would be named {key}, the name of another run already measured: keep each "
                         "configuration's runs in their own folder")
    runs[key] = entry


def parse_pairs(texts: list[str]) -> list[tuple[Path, Path]]:
    """Command-line pairs ``A=B`` as two absolute paths each."""
    pairs = [tuple(Path(side).absolute() for side in text.split("=", 1)) for text in texts]
    for text, pair in zip(texts, pairs):
        if len(pair) != 2:
            raise ValueError(f"{text!r} is no pair: write RUN_A=RUN_B")
    return pairs


def paired_fields(found: dict, sides: tuple[str, str], records: tuple[dict, dict], runs: tuple[str, str],
                  episodes: int, seed: int) -> dict:
    """A paired row's figures from ``compare_runs``' result ``found`` (side a minus side b): the difference and its
    interval, then each side's score, iterations and run name under its name in ``sides``, and the episodes."""
    (a, b), (record_a, record_b), (run_a, run_b) = sides, records, runs
    return {"paired_difference": found["mean_difference"], "ci95": found["ci95"],
            f"{a}_score": found["mean_score_a"], f"{b}_score": found["mean_score_b"],
            f"{a}_iterations": record_a["iterations"], f"{b}_iterations": record_b["iterations"],
            f"{a}_run": run_a, f"{b}_run": run_b, "episodes": episodes, "episode_seed": seed}


def load(out: Path, lists: tuple[str, ...]) -> dict:
    """The JSON at ``out`` (empty when absent), with each of ``lists`` and the ``runs`` map present."""
    data = json.loads(out.read_text()) if out.exists() else {}
    for name in lists:
        data.setdefault(name, [])
    data.setdefault("runs", {})
    return data


def write(out: Path, data: dict) -> None:
    """Atomically: a batch stopped mid-write leaves the previous file."""
    tmp = out.with_name(out.name + ".tmp")
    tmp.write_text(json.dumps(data, indent=1, sort_keys=True) + "\n")
    tmp.replace(out)


def env_decimals(summary: Path = SUMMARY) -> dict:
    """Each environment's decimals, as every results page writes its scores (docs/results/summary.json)."""
    return {env["env"]: env["decimals"] for env in json.loads(summary.read_text())["environments"]}


def signed(value: float | None, decimals: int = 3) -> str:
    return "" if value is None else f"{value:+.{decimals}f}"


def interval(row: dict, decimals: int = 3) -> str:
    """A row's paired difference with its 95% interval."""
    low, high = row["ci95"]
    return f"{row['paired_difference']:+.{decimals}f} ({low:+.{decimals}f}, {high:+.{decimals}f})"


def seeds_clear_of_zero(rows: list[dict]) -> tuple[float, int, int]:
    """(mean paired difference, seeds whose interval lies above zero, seeds whose interval lies below it)."""
    mean = sum(row["paired_difference"] for row in rows) / len(rows)
    return mean, sum(row["ci95"][0] > 0 for row in rows), sum(row["ci95"][1] < 0 for row in rows)


def mean_and_count(rows: list[dict], places: int) -> str:
    mean, above, below = seeds_clear_of_zero(rows)
    return (f"{mean:+.{places}f} (of {len(rows)} seed{'s' if len(rows) != 1 else ''}: {below} below zero, "
            f"{above} above)")


def render_blocks(text: str, begin_format: str, tables: dict[str, Callable[[dict, dict], list[str]]], data: dict,
                  decimals: dict) -> str:
    """``text`` with each generated block (from ``begin_format`` naming it, to ``END``) replaced by its table."""
    for name, table in tables.items():
        begin = begin_format.format(name=name)
        if begin not in text:
            continue
        head, rest = text.split(begin, 1)
        _, tail = rest.split(END, 1)
        text = head + begin + "\n" + "\n".join(table(data, decimals)) + "\n" + END + tail
    return text
