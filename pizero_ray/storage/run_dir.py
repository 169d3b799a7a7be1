"""A run directory: config.json, evaluation.json, metrics.jsonl and checkpoints/.

evaluation.json keeps the run's schedule: the learning curve's (how often,
how many episodes, on which environment parameters) and the checkpoints'
(how often, how many kept), so that ``pizero resume`` goes on as the run
started unless told otherwise.

Nothing here deletes a row: those a resume takes out of metrics.jsonl go to
metrics-dropped.jsonl.

A run dir is data, and reading one runs no code of its own: an environment
recorded by import path (``module:factory``) is imported only when the user
trusts it again (``read_trusted_config``): names it on the command line, or
says ``--trust-env``. Registered environments load by name.

Paths are made absolute at the edge: ``ray job submit`` runs the entrypoint in
a temporary working directory, so a relative run dir would land there.
"""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

from pizero_ray.config import Config, ConfigError

CONFIG_FILE = "config.json"
METRICS_FILE = "metrics.jsonl"
DROPPED_METRICS_FILE = "metrics-dropped.jsonl"  # rows a resume or restart took out of metrics.jsonl
EVALUATION_FILE = "evaluation.json"


def resolve(run_dir: str | os.PathLike) -> Path:
    return Path(run_dir).expanduser().absolute()


def check_location(run_dir: Path) -> None:
    """A one-line ConfigError unless ``run_dir`` can be a run dir: no file in its place or above it, and the
    nearest existing directory on its path writable (as far as permissions and a read-only mount tell)."""
    for path in (run_dir, *run_dir.parents):
        if not path.exists():
            continue
        if not path.is_dir():
            raise ConfigError(f"run dir {run_dir}: {path} is a file, not a directory")
        if not os.access(path, os.W_OK | os.X_OK):
            raise ConfigError(f"run dir {run_dir}: {path} is not writable")
        return


def _replace_file(run_dir: Path, name: str, text: str) -> None:
    """Writes ``run_dir/name`` whole: a temporary file renamed into place, so never half-written."""
    run_dir.mkdir(parents=True, exist_ok=True)
    tmp = run_dir / (name + ".tmp")
    tmp.write_text(text)
    os.replace(tmp, run_dir / name)


def write_config(run_dir: Path, config: Config) -> None:
    _replace_file(run_dir, CONFIG_FILE, config.to_json() + "\n")


def write_schedule(run_dir: Path, schedule: dict) -> None:
    """The evaluation and checkpoint settings by RunOptions field name (``RunOptions.schedule``)."""
    _replace_file(run_dir, EVALUATION_FILE, json.dumps(schedule, sort_keys=True) + "\n")


def read_schedule(run_dir: Path) -> dict:
    """What ``write_schedule`` wrote; {} for a run dir without one (written before it existed). Anything but an
    object of known settings is a one-line ConfigError naming the file."""
    from pizero_ray.trainer.options import SCHEDULE_FIELDS

    path = run_dir / EVALUATION_FILE
    if not path.is_file():
        return {}
    try:
        schedule = json.loads(path.read_text())
    except json.JSONDecodeError as error:
        raise ConfigError(f"{path} is not valid JSON: {error}") from None
    if not isinstance(schedule, dict):
        raise ConfigError(f"{path} must hold a JSON object of settings, got {type(schedule).__name__}")
    unknown = sorted(set(schedule) - set(SCHEDULE_FIELDS))
    if unknown:
        raise ConfigError(f"{path} holds unknown settings {', '.join(map(repr, unknown))} "
                          f"(known: {', '.join(SCHEDULE_FIELDS)})")
    return schedule


def read_config(run_dir: Path) -> Config:
    path = run_dir / CONFIG_FILE
    if not run_dir.is_dir():
        raise ConfigError(f"run dir {run_dir} does not exist")
    if not path.is_file():
        raise ConfigError(f"{path} is missing: {run_dir} is not a pizero run dir")
    try:
        return Config.from_json(path.read_text()).validate()
    except (json.JSONDecodeError, TypeError) as error:
        raise ConfigError(f"{path} is not a valid config: {error}") from None


def read_trusted_config(run_dir: Path, trust_env: bool | str = False) -> Config:
    """``read_config``, refusing a run dir whose environment would run code the user has not named.

    ``trust_env``: True trusts whatever the run dir names (``--trust-env``); a
    text trusts that one import path (the environment the user named with
    ``--env``); False trusts registered environments only. Building an
    environment named by import path imports its module, so a run dir received
    from elsewhere would otherwise be executable input.
    """
    from pizero_ray import envs

    config = read_config(run_dir)
    if envs.is_import_path(config.env) and not (trust_env is True or trust_env == config.env):
        raise ConfigError(f"run dir {run_dir} names its environment by import path {config.env!r}, which would "
                          f"import and run that code; if you trust the run dir, add --env {config.env} or "
                          "--trust-env")
    return config


def _metrics_lines(run_dir: Path) -> tuple[list[dict], list[str]]:
    """(the readable rows, the raw lines from the first unreadable one on)."""
    path = run_dir / METRICS_FILE
    if not path.is_file():
        return [], []
    lines = [line.strip() for line in path.read_text().splitlines() if line.strip()]
    rows = []
    for index, line in enumerate(lines):
        try:
            row = json.loads(line)
        except json.JSONDecodeError:
            row = None
        if not _is_row(row):
            return rows, lines[index:]  # a line cut short by a crash (or no row at all) ends the readable log
        rows.append(row)
    return rows, []


def _is_row(row) -> bool:
    """A metrics row: a JSON object with a whole, non-negative iteration."""
    iteration = row.get("iteration") if isinstance(row, dict) else None
    return isinstance(iteration, int) and not isinstance(iteration, bool) and iteration >= 0


def read_metrics(run_dir: Path) -> list[dict]:
    return _metrics_lines(run_dir)[0]


def evaluated_rows(run_dir: Path) -> list[dict]:
    """The metrics rows that carry a learning-curve evaluation, oldest first ([] before the first is written)."""
    return [row for row in read_metrics(run_dir) if "eval_mean_score" in row]


def rewrite_metrics(run_dir: Path, rows: list[dict]) -> None:
    """Replaces metrics.jsonl with exactly ``rows`` (atomically, on disk before it returns)."""
    path = run_dir / METRICS_FILE
    tmp = path.with_name(METRICS_FILE + ".tmp")
    _write_synced(tmp, "".join(json.dumps(row, sort_keys=True) + "\n" for row in rows), "w")
    os.replace(tmp, path)


def keep_metrics_through(run_dir: Path, iteration: int, reason: str) -> list[dict]:
    """Cuts metrics.jsonl to the rows up to ``iteration`` and returns them.

    The rows above it, and any unreadable tail, are appended to
    metrics-dropped.jsonl before metrics.jsonl is rewritten: a crash in between
    leaves them in both files, never in neither.
    """
    rows, unreadable = _metrics_lines(run_dir)
    kept = [row for row in rows if row["iteration"] <= iteration]
    dropped = [row for row in rows if row["iteration"] > iteration]
    if unreadable:
        print(f"pizero: warning: {run_dir / METRICS_FILE} has {len(unreadable)} unreadable line(s) from line "
              f"{len(rows) + 1} on (a write cut short?); moved to {run_dir / DROPPED_METRICS_FILE}", file=sys.stderr)
    if dropped or unreadable:
        stamp = time.strftime("%Y-%m-%dT%H:%M:%S%z")
        records = [{"dropped_at": stamp, "reason": reason, "row": row} for row in dropped]
        records += [{"dropped_at": stamp, "reason": reason, "unreadable_line": line} for line in unreadable]
        _write_synced(run_dir / DROPPED_METRICS_FILE,
                      "".join(json.dumps(record, sort_keys=True) + "\n" for record in records), "a")
        rewrite_metrics(run_dir, kept)
    return kept


def _write_synced(path: Path, text: str, mode: str) -> None:
    with open(path, mode, encoding="utf-8") as file:
        file.write(text)
        file.flush()
        os.fsync(file.fileno())


class MetricsLog:
    """Appends one JSON object per iteration, flushed and fsynced as it goes."""

    def __init__(self, run_dir: Path):
        self._file = open(run_dir / METRICS_FILE, "a", encoding="utf-8")

    def write(self, row: dict) -> None:
        self._file.write(json.dumps(row, sort_keys=True) + "\n")
        self._file.flush()
        os.fsync(self._file.fileno())

    def close(self) -> None:
        self._file.close()
