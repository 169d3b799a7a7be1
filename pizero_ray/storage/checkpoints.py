"""Orbax checkpoints of everything needed to continue training.

Layout: RUN_DIR/checkpoints/<iteration>/{state, meta}. ``state`` holds the flat
parameters (item ``theta``) and everything else training carries (item
``opt_state``: the optax state, Adam's moments and count, and for the
gradient-trained baselines the replay buffer too) as arrays;
``meta`` is JSON (iteration, seed, config, parameter hash, and a hash of the
whole state). Orbax writes a step into a temporary directory and renames it
when complete, so a save that dies half-way is never listed as a step; the
hash catches a finished checkpoint damaged later. After Orbax's save, a file
manifest (size and sha256 of every file it wrote) goes into the step dir, so
that a failed restore can tell damaged files (quarantined, the previous
checkpoint tried) from anything else (an I/O error, a changed optimiser state
structure: the run stops and nothing is moved). No pickle anywhere.
"""

from __future__ import annotations

import hashlib
import json
import logging
import os
import sys
import time
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np

from pizero_ray.storage import run_dir as rundir

CHECKPOINT_DIR = "checkpoints"
CORRUPT_DIR = "checkpoints-corrupt"
MANIFEST_FILE = "pizero-manifest.json"
ITEMS = ("state", "meta")


class Checkpoint(NamedTuple):
    iteration: int
    theta: np.ndarray
    carried: Any
    meta: dict


class CheckpointError(RuntimeError):
    pass


class CheckpointSaveError(CheckpointError):
    """A checkpoint could not be written (a full disk, a lost mount): training stops; earlier ones stand."""


class CorruptCheckpoint(CheckpointError):
    """A checkpoint shown to be damaged: a hash mismatch, or files missing or changed since the save."""


def _manager(run_dir: Path, max_to_keep: int | None = None):
    import orbax.checkpoint as ocp  # lazily: the CLI's error paths should not pay for Orbax

    options = ocp.CheckpointManagerOptions(
        max_to_keep=max_to_keep, create=True, enable_async_checkpointing=False
    )
    return ocp.CheckpointManager(
        Path(run_dir).absolute() / CHECKPOINT_DIR, options=options, item_names=ITEMS
    )


class CheckpointWriter:
    """Saves checkpoints of one run, keeping the newest ``max_to_keep``."""

    def __init__(self, run_dir: Path, max_to_keep: int = 3):
        logging.getLogger("absl").setLevel(logging.WARNING)
        self._manager = _manager(run_dir, max_to_keep)

    def save(self, iteration: int, theta: np.ndarray, carried: Any, meta: dict) -> None:
        if iteration in self._manager.all_steps():
            return
        state = {"theta": np.asarray(theta), "opt_state": carried}
        meta = {**meta, "state_hash": state_hash(state["theta"], carried)}
        import orbax.checkpoint as ocp

        try:
            self._manager.save(
                iteration,
                args=ocp.args.Composite(state=ocp.args.StandardSave(state), meta=ocp.args.JsonSave(meta)),
            )
            self._manager.wait_until_finished()
            write_manifest(Path(self._manager.directory) / str(iteration))
        except Exception as error:  # Orbax and TensorStore raise many kinds (RESOURCE_EXHAUSTED on a full disk)
            # Orbax never lists an unfinished step; the step dir of a save that failed after it did (at the
            # manifest) has no manifest and is judged by its files on restore.
            raise CheckpointSaveError(f"saving the checkpoint of iteration {iteration} to "
                                      f"{self._manager.directory} failed: {_cause(error)}") from error

    def close(self) -> None:
        self._manager.close()


def checkpoint_steps(run_dir: Path) -> list[int]:
    """Finished checkpoints (Orbax lists only steps whose save completed)."""
    directory = Path(run_dir).absolute() / CHECKPOINT_DIR
    if directory.exists() and not directory.is_dir():
        raise CheckpointError(f"{directory} is not a directory: the run's checkpoints cannot be read")
    if not directory.is_dir():
        return []
    manager = _manager(run_dir)
    steps = sorted(manager.all_steps())
    manager.close()
    return steps


def newest_meta(run_dir: Path) -> dict | None:
    """The ``meta`` item (iteration, seed, config, hashes) of the newest checkpoint whose meta reads; None if
    none does. Reads no arrays: cheap enough to check a run dir before anything is written to it."""
    import orbax.checkpoint as ocp

    steps = checkpoint_steps(run_dir)
    if not steps:
        return None
    manager = _manager(run_dir)
    try:
        for step in reversed(steps):
            try:
                return dict(manager.restore(step, args=ocp.args.Composite(meta=ocp.args.JsonRestore()))["meta"])
            except Exception:  # noqa: BLE001 -- a damaged step: restore_latest reports it; try the one before
                continue
    finally:
        manager.close()
    return None


def state_hash(theta: np.ndarray, carried: Any) -> str:
    """sha256 over the parameters and every optimiser leaf: detects corruption Orbax cannot see."""
    import jax

    digest = hashlib.sha256()
    for leaf in [theta, *jax.tree_util.tree_leaves(carried)]:
        array = np.asarray(leaf)
        digest.update(str(array.dtype).encode() + str(array.shape).encode())
        digest.update(np.ascontiguousarray(array).tobytes())
    return digest.hexdigest()


def _sha256(path: Path) -> str:
    digest = hashlib.sha256()
    with open(path, "rb") as file:
        for block in iter(lambda: file.read(1 << 20), b""):
            digest.update(block)
    return digest.hexdigest()


def _files_under(directory: Path) -> list[Path]:
    """Every file below ``directory``, sorted; raises OSError rather than skip what it cannot list."""

    def fail(error: OSError):
        raise error

    return sorted(Path(root) / name for root, _, names in os.walk(directory, onerror=fail) for name in names)


def _step_files(step_dir: Path) -> list[Path]:
    """The files Orbax wrote into a step dir: all but the manifest (and its temporary)."""
    return [p for p in _files_under(step_dir) if not (p.parent == step_dir and p.name.startswith(MANIFEST_FILE))]


def write_manifest(step_dir: Path) -> None:
    """Records the size and sha256 of every file of a finished save: what diagnose() compares against."""
    files = {p.relative_to(step_dir).as_posix(): {"size": p.stat().st_size, "sha256": _sha256(p)}
             for p in _step_files(step_dir)}
    tmp = step_dir / (MANIFEST_FILE + ".tmp")
    with open(tmp, "w", encoding="utf-8") as file:
        file.write(json.dumps({"files": files}, sort_keys=True))
        file.flush()
        os.fsync(file.fileno())
    os.replace(tmp, step_dir / MANIFEST_FILE)  # never a half-written manifest


class Diagnosis(NamedTuple):
    verdict: str  # "damaged", "intact" (as the manifest says), "unverified" (no manifest), "unreadable"
    detail: str  # says why, to finish a sentence about the checkpoint


def diagnose(step_dir: Path) -> Diagnosis:
    """What a step dir's files say about it; only "damaged" shows it corrupt. An I/O error here shows nothing."""
    try:
        manifest = _read_manifest(step_dir)
        if manifest is None:
            return _check_structure(step_dir)
        return _check_manifest(step_dir, manifest)
    except OSError as error:
        return Diagnosis("unreadable", f"its files could not be checked ({error})")


def _read_manifest(step_dir: Path) -> dict | None:
    """{relative path: {size, sha256}}; None without one (older checkpoints) or if it is garbled."""
    path = step_dir / MANIFEST_FILE
    if not path.exists():
        return None
    try:
        files = json.loads(path.read_text(encoding="utf-8"))["files"]
        return {str(name): (int(entry["size"]), str(entry["sha256"])) for name, entry in files.items()}
    except (ValueError, KeyError, TypeError, AttributeError):
        return None  # a damaged manifest says nothing about the data: judge by structure alone


def _check_manifest(step_dir: Path, manifest: dict) -> Diagnosis:
    for name, (size, sha256) in sorted(manifest.items()):
        path = step_dir / name
        if not path.is_file():
            return Diagnosis("damaged", f"{name} is missing")
        if path.stat().st_size != size:
            return Diagnosis("damaged", f"{name} is {path.stat().st_size} bytes, {size} when saved")
        if _sha256(path) != sha256:
            return Diagnosis("damaged", f"{name} has changed since the save (sha256)")
    return Diagnosis("intact", "its files are as saved")


def _check_structure(step_dir: Path) -> Diagnosis:
    """Without a manifest (an older checkpoint, or a crash just after Orbax's rename) only visible damage counts."""
    for item in ITEMS:
        if not (step_dir / item).is_dir():
            return Diagnosis("damaged", f"its {item} directory is missing")
        if not _files_under(step_dir / item):
            return Diagnosis("damaged", f"its {item} directory holds no files")
    for path in _step_files(step_dir):
        if path.stat().st_size == 0:
            return Diagnosis("damaged", f"{path.relative_to(step_dir).as_posix()} is empty")
    return Diagnosis("unverified", "it has no file manifest and its files look complete")


def _cause(error: BaseException) -> str:
    first = str(error).splitlines()[0].rstrip(": ") if str(error) else ""
    return f"{type(error).__name__}: {first}"[:300] if first else type(error).__name__


def _restore_step(manager, step: int, target: dict) -> Checkpoint:
    """One checkpoint; CorruptCheckpoint if shown damaged, CheckpointError if it fails for any other reason."""
    import orbax.checkpoint as ocp

    path = Path(manager.directory) / str(step)
    try:
        restored = manager.restore(
            step, args=ocp.args.Composite(state=ocp.args.StandardRestore(target), meta=ocp.args.JsonRestore())
        )
        state, meta = restored["state"], dict(restored["meta"])
    except Exception as error:  # Orbax and TensorStore raise many kinds: the files tell damage from the rest
        found = diagnose(path)
        if found.verdict == "damaged":
            raise CorruptCheckpoint(f"checkpoint {path} is corrupt: {found.detail} ({_cause(error)})") from error
        raise CheckpointError(f"cannot restore checkpoint {path}: {_cause(error)}; not treated as corrupt "
                              f"because {found.detail}") from error
    theta = np.asarray(state["theta"])
    if meta.get("state_hash") != state_hash(theta, state["opt_state"]):
        found = diagnose(path)
        if found.verdict in ("intact", "unreadable"):
            # Files as saved but other contents: the restore read them differently (a new dtype, say).
            raise CheckpointError(f"checkpoint {path} restored to contents that do not match its hash, but "
                                  f"{found.detail}: not treated as corrupt")
        raise CorruptCheckpoint(f"checkpoint {path} is corrupt: its contents do not match the hash saved with it")
    return Checkpoint(step, theta, state["opt_state"], meta)


def restore_latest(
    run_dir: Path, theta_template: np.ndarray, carried_template: Any, quarantine_corrupt: bool = False
) -> Checkpoint | None:
    """The newest good checkpoint, restored into the templates' structure; None if there is none.

    A checkpoint shown to be corrupt (see diagnose) is reported on stderr by
    path and the previous one is tried. With ``quarantine_corrupt`` (resuming),
    it is moved to checkpoints-corrupt/ (kept, never deleted) so that training
    can save that step again. Any other failure raises CheckpointError at once:
    falling back to an older checkpoint would silently drop progress. If
    checkpoints exist but none is readable, raises.
    """
    steps = checkpoint_steps(run_dir)
    if not steps:
        return None
    target = {"theta": np.asarray(theta_template), "opt_state": carried_template}
    manager = _manager(run_dir)
    errors = []
    try:
        for step in reversed(steps):
            try:
                return _restore_step(manager, step, target)
            except CorruptCheckpoint as error:
                errors.append(str(error))
                print(f"pizero: warning: {error}; trying the previous checkpoint", file=sys.stderr)
                if quarantine_corrupt:
                    _quarantine(Path(manager.directory) / str(step))
    finally:
        manager.close()
    moved = f"; all moved to {Path(run_dir).absolute() / CORRUPT_DIR}" if quarantine_corrupt else ""
    raise CheckpointError(f"no readable checkpoint in {Path(run_dir).absolute() / CHECKPOINT_DIR}{moved}: {errors[0]}")


def _unused(path: Path) -> Path:
    """``path``, or ``path-1``, ``path-2``, ... whichever does not exist yet."""
    candidate, number = path, 0
    while candidate.exists():
        number += 1
        candidate = path.with_name(f"{path.name}-{number}")
    return candidate


def _move(source: Path, destination: Path) -> None:
    try:
        destination.parent.mkdir(parents=True, exist_ok=True)
        os.replace(source, destination)
    except OSError as error:
        raise CheckpointError(f"cannot move {source} to {destination}: {error}") from error
    print(f"pizero: warning: moved {source} to {destination}", file=sys.stderr)


def _quarantine(path: Path) -> None:
    _move(path, _unused(path.parent.parent / CORRUPT_DIR / f"{path.name}-{time.strftime('%Y%m%d-%H%M%S')}"))


def _count(number: int, noun: str) -> str:
    return f"{number} {noun}" if number == 1 else f"{number} {noun}s"


def held_progress(run_dir: Path) -> list[str]:
    """What in a run dir is training progress, described; empty if starting from iteration 0 loses nothing.

    The metrics row of iteration 0 (the untrained agent's evaluation) is no progress.
    """
    held = []
    steps = checkpoint_steps(run_dir)
    if steps:
        held.append(f"{_count(len(steps), 'checkpoint')} in {run_dir / CHECKPOINT_DIR}")
    corrupt_dir = run_dir / CORRUPT_DIR
    quarantined = len(list(corrupt_dir.iterdir())) if corrupt_dir.is_dir() else 0
    if quarantined:
        held.append(f"{_count(quarantined, 'quarantined checkpoint')} in {corrupt_dir}")
    rows = sum(1 for row in rundir.read_metrics(run_dir) if row["iteration"] > 0)
    if rows:
        held.append(_count(rows, "metrics row"))
    return held


class Resume(NamedTuple):
    iteration: int
    theta: np.ndarray
    carried: Any
    metrics: list[dict]  # metrics.jsonl's rows, now cut to ``iteration``


def prepare_resume(run_dir: Path, theta_template: np.ndarray, carried_template: Any,
                   restart: bool = False) -> Resume:
    """Where training continues, with metrics.jsonl cut to match; the one place a resume changes a run dir.

    From the newest good checkpoint (corrupt ones quarantined); any other
    restore failure raises and changes nothing. Without a checkpoint, a run dir
    holding progress is refused unless ``restart``, which moves what it
    replaces to replaced/<time>/ and metrics-dropped.jsonl. Metrics rows above
    the starting iteration go to metrics-dropped.jsonl: no row is ever deleted.
    """
    run_dir = Path(run_dir).absolute()
    if restart:
        _set_aside(run_dir)  # checkpoints first: a crash before the metrics leaves rows, so the next resume refuses
        metrics = rundir.keep_metrics_through(run_dir, -1, "pizero resume --restart: started again from iteration 0")
        return Resume(0, np.asarray(theta_template), carried_template, metrics)
    restored = restore_latest(run_dir, theta_template, carried_template, quarantine_corrupt=True)
    if restored is None:
        held = held_progress(run_dir)
        if held:
            raise CheckpointError(f"run dir {run_dir} holds {' and '.join(held)} but no checkpoint to continue "
                                  f"from; to start again from iteration 0, keeping what it replaces, add --restart")
        restored = Checkpoint(0, np.asarray(theta_template), carried_template, {})
    metrics = rundir.keep_metrics_through(run_dir, restored.iteration,
                                          f"resumed from the checkpoint of iteration {restored.iteration}")
    return Resume(restored.iteration, restored.theta, restored.carried, metrics)


def _set_aside(run_dir: Path) -> None:
    """Moves checkpoints/ and checkpoints-corrupt/ into replaced/<time>/: a restart keeps what it replaces."""
    present = [run_dir / name for name in (CHECKPOINT_DIR, CORRUPT_DIR)
               if (run_dir / name).is_dir() and any((run_dir / name).iterdir())]
    if present:
        destination = _unused(run_dir / "replaced" / time.strftime("%Y%m%d-%H%M%S"))
        for path in present:
            _move(path, destination / path.name)
