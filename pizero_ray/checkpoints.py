"""Orbax checkpoints of everything needed to continue training.

Layout: RUN_DIR/checkpoints/<iteration>/{state, meta}. ``state`` holds the flat
parameters and the complete optax state (Adam moments and count) as arrays;
``meta`` is JSON (iteration, seed, config, metrics position). Orbax writes a
step into a temporary directory and renames it when complete, so a save that
dies half-way is never listed as a step. No pickle anywhere.
"""

from __future__ import annotations

import logging
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import orbax.checkpoint as ocp

CHECKPOINT_DIR = "checkpoints"


class Checkpoint(NamedTuple):
    iteration: int
    theta: np.ndarray
    opt_state: Any
    meta: dict


class CheckpointError(RuntimeError):
    pass


def _manager(run_dir: Path, max_to_keep: int | None = None) -> ocp.CheckpointManager:
    options = ocp.CheckpointManagerOptions(
        max_to_keep=max_to_keep, create=True, enable_async_checkpointing=False
    )
    return ocp.CheckpointManager(
        Path(run_dir).absolute() / CHECKPOINT_DIR, options=options, item_names=("state", "meta")
    )


class CheckpointWriter:
    """Saves checkpoints of one run, keeping the newest ``max_to_keep``."""

    def __init__(self, run_dir: Path, max_to_keep: int = 3):
        logging.getLogger("absl").setLevel(logging.WARNING)
        self._manager = _manager(run_dir, max_to_keep)

    def save(self, iteration: int, theta: np.ndarray, opt_state: Any, meta: dict) -> None:
        if iteration in self._manager.all_steps():
            return
        state = {"theta": np.asarray(theta), "opt_state": opt_state}
        self._manager.save(
            iteration,
            args=ocp.args.Composite(state=ocp.args.StandardSave(state), meta=ocp.args.JsonSave(meta)),
        )
        self._manager.wait_until_finished()

    def close(self) -> None:
        self._manager.close()


def checkpoint_steps(run_dir: Path) -> list[int]:
    directory = Path(run_dir).absolute() / CHECKPOINT_DIR
    if not directory.is_dir():
        return []
    manager = _manager(run_dir)
    steps = sorted(manager.all_steps())
    manager.close()
    return steps


def restore_latest(run_dir: Path, theta_template: np.ndarray, opt_state_template: Any) -> Checkpoint | None:
    """The newest checkpoint, restored into the templates' structure; None if there is none."""
    steps = checkpoint_steps(run_dir)
    if not steps:
        return None
    manager = _manager(run_dir)
    step = steps[-1]
    target = {"theta": np.asarray(theta_template), "opt_state": opt_state_template}
    try:
        restored = manager.restore(
            step, args=ocp.args.Composite(state=ocp.args.StandardRestore(target), meta=ocp.args.JsonRestore())
        )
    except Exception as error:  # orbax raises many kinds; name the checkpoint either way
        raise CheckpointError(f"cannot read checkpoint {manager.directory / str(step)}: {error}") from error
    finally:
        manager.close()
    state = restored["state"]
    return Checkpoint(step, np.asarray(state["theta"]), state["opt_state"], dict(restored["meta"]))
