"""TensorBoard event files beside metrics.jsonl, so ``tensorboard --logdir DIR`` shows runs live.

metrics.jsonl stays the source of truth: the event files only mirror its
numeric fields (one scalar per field, the iteration as the step, each row's
wall-clock as its time). Rows a resume drops from metrics.jsonl stay in the
older event files; TensorBoard shows the newer values at the same steps.
"""

from __future__ import annotations

import numbers
from pathlib import Path

EVENTS_DIR = "tensorboard"


class EventLog:
    """Mirrors metrics rows into RUN_DIR/tensorboard/, flushed as they come."""

    def __init__(self, run_dir: Path):
        from tensorboardX import SummaryWriter  # lazily: only training writes events

        self._writer = SummaryWriter(logdir=str(Path(run_dir) / EVENTS_DIR), flush_secs=5)

    def write(self, row: dict) -> None:
        step = int(row["iteration"])
        for name, value in row.items():
            if name != "iteration" and isinstance(value, numbers.Real) and not isinstance(value, bool):
                self._writer.add_scalar(f"pizero/{name}", float(value), global_step=step)
        self._writer.flush()

    def close(self) -> None:
        self._writer.close()
