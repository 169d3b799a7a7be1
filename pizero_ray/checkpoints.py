"""Orbax checkpoints of everything needed to continue training.

Layout: RUN_DIR/checkpoints/<iteration>/{state, meta}. ``state`` holds the flat
parameters and the complete optax state (Adam moments and count) as arrays;
``meta`` is JSON (iteration, seed, config, metrics position, and a hash of the
whole state). Orbax writes a step into a temporary directory and renames it
when complete, so a save that dies half-way is never listed as a step; the
hash catches a finished checkpoint damaged later. No pickle anywhere.
"""

from __future__ import annotations

import hashlib
import logging
import os
import sys
import time
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

CHECKPOINT_DIR = "checkpoints"


class Checkpoint(NamedTuple):
    iteration: int
    theta: np.ndarray
    opt_state: Any
    meta: dict


class CheckpointError(RuntimeError):
    pass


def _manager(run_dir: Path, max_to_keep: int | None = None):
    import orbax.checkpoint as ocp  # lazily: the CLI's error paths should not pay for Orbax

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
        meta = {**meta, "state_hash": state_hash(state["theta"], opt_state)}
        import orbax.checkpoint as ocp

        self._manager.save(
            iteration,
            args=ocp.args.Composite(state=ocp.args.StandardSave(state), meta=ocp.args.JsonSave(meta)),
        )
        self._manager.wait_until_finished()

    def close(self) -> None:
        self._manager.close()


def checkpoint_steps(run_dir: Path) -> list[int]:
    """Finished checkpoints (Orbax lists only steps whose save completed)."""
    directory = Path(run_dir).absolute() / CHECKPOINT_DIR
    if not directory.is_dir():
        return []
    manager = _manager(run_dir)
    steps = sorted(manager.all_steps())
    manager.close()
    return steps


def state_hash(theta: np.ndarray, opt_state: Any) -> str:
    """sha256 over the parameters and every optimiser leaf: detects corruption Orbax cannot see."""
    import jax

    digest = hashlib.sha256()
    for leaf in [theta, *jax.tree_util.tree_leaves(opt_state)]:
        array = np.asarray(leaf)
        digest.update(str(array.dtype).encode() + str(array.shape).encode())
        digest.update(np.ascontiguousarray(array).tobytes())
    return digest.hexdigest()


def _restore_step(manager, step: int, target: dict) -> Checkpoint:
    import orbax.checkpoint as ocp

    path = Path(manager.directory) / str(step)
    try:
        restored = manager.restore(
            step, args=ocp.args.Composite(state=ocp.args.StandardRestore(target), meta=ocp.args.JsonRestore())
        )
        state, meta = restored["state"], dict(restored["meta"])
    except Exception as error:  # Orbax and TensorStore raise many kinds; name the checkpoint either way
        reason = str(error).splitlines()[0] if str(error) else type(error).__name__
        raise CheckpointError(f"checkpoint {path} is unreadable: {reason[:300]}") from error
    theta = np.asarray(state["theta"])
    if meta.get("state_hash") != state_hash(theta, state["opt_state"]):
        raise CheckpointError(f"checkpoint {path} is corrupt: its contents do not match the hash saved with it")
    return Checkpoint(step, theta, state["opt_state"], meta)


def restore_latest(
    run_dir: Path, theta_template: np.ndarray, opt_state_template: Any, quarantine_corrupt: bool = False
) -> Checkpoint | None:
    """The newest good checkpoint, restored into the templates' structure; None if there is none.

    A corrupt or truncated checkpoint is reported on stderr by path and the
    previous one is tried. With ``quarantine_corrupt`` (resuming), a bad one is
    moved to checkpoints-corrupt/ (kept, never deleted) so that training can
    save that step again. If checkpoints exist but none is readable, raises.
    """
    steps = checkpoint_steps(run_dir)
    if not steps:
        return None
    target = {"theta": np.asarray(theta_template), "opt_state": opt_state_template}
    manager = _manager(run_dir)
    errors = []
    try:
        for step in reversed(steps):
            try:
                return _restore_step(manager, step, target)
            except CheckpointError as error:
                errors.append(str(error))
                print(f"pizero: warning: {error}; trying the previous checkpoint", file=sys.stderr)
                if quarantine_corrupt:
                    _quarantine(Path(manager.directory) / str(step))
    finally:
        manager.close()
    raise CheckpointError(f"no readable checkpoint in {Path(run_dir).absolute() / CHECKPOINT_DIR}: {errors[0]}")


def _quarantine(path: Path) -> None:
    corrupt_dir = path.parent.parent / "checkpoints-corrupt"
    corrupt_dir.mkdir(exist_ok=True)
    destination = corrupt_dir / f"{path.name}-{time.strftime('%Y%m%d-%H%M%S')}"
    os.replace(path, destination)
    print(f"pizero: warning: moved {path} to {destination}", file=sys.stderr)
