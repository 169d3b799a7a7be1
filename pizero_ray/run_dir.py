"""A run directory: config.json, metrics.jsonl and checkpoints/.

Paths are made absolute at the edge: ``ray job submit`` runs the entrypoint in
a temporary working directory, so a relative run dir would land there.
"""

from __future__ import annotations

import json
import os
from pathlib import Path
from typing import Iterable

from pizero_ray.config import Config, ConfigError

CONFIG_FILE = "config.json"
METRICS_FILE = "metrics.jsonl"


def resolve(run_dir: str | os.PathLike) -> Path:
    return Path(run_dir).expanduser().absolute()


def write_config(run_dir: Path, config: Config) -> None:
    run_dir.mkdir(parents=True, exist_ok=True)
    tmp = run_dir / (CONFIG_FILE + ".tmp")
    tmp.write_text(config.to_json() + "\n")
    os.replace(tmp, run_dir / CONFIG_FILE)  # never a half-written config


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


def read_metrics(run_dir: Path) -> list[dict]:
    path = run_dir / METRICS_FILE
    if not path.is_file():
        return []
    rows = []
    for line in path.read_text().splitlines():
        line = line.strip()
        if line:
            try:
                rows.append(json.loads(line))
            except json.JSONDecodeError:
                break  # a line cut short by a crash ends the readable log
    return rows


def rewrite_metrics(run_dir: Path, rows: list[dict]) -> None:
    """Replaces metrics.jsonl with exactly ``rows`` (atomically): resume keeps the rows up to its checkpoint."""
    path = run_dir / METRICS_FILE
    tmp = path.with_name(METRICS_FILE + ".tmp")
    tmp.write_text("".join(json.dumps(row, sort_keys=True) + "\n" for row in rows))
    os.replace(tmp, path)


class MetricsLog:
    """Appends one JSON object per iteration, flushed and fsynced as it goes."""

    def __init__(self, run_dir: Path):
        self._file = open(run_dir / METRICS_FILE, "a", encoding="utf-8")

    def write(self, row: dict) -> None:
        self._file.write(json.dumps(row, sort_keys=True) + "\n")
        self._file.flush()
        os.fsync(self._file.fileno())

    def write_all(self, rows: Iterable[dict]) -> None:
        for row in rows:
            self.write(row)

    def close(self) -> None:
        self._file.close()
