"""One writer per run dir: the process training a run holds its lock until it is done.

A retried job can start while the old one still runs; two processes writing
one run dir would interleave its checkpoints and metrics. The lock is an
``flock`` on RUN_DIR/writer.lock, which names its holder (pid, host, command,
since when): a second writer is refused in one line naming the holder, before
it writes anything. The kernel drops the lock when its process ends, however
it ends, so a lock file left by a dead process blocks nothing. A process may
take the lock it holds again (the CLI holds it around the driver, which takes
it too).
"""

from __future__ import annotations

import contextlib
import fcntl
import json
import os
import socket
import sys
import time
from pathlib import Path

LOCK_FILE = "writer.lock"

_held: dict[Path, list[int]] = {}  # run dir -> [the lock's fd, how many holds]: this process's locks


class RunDirInUse(RuntimeError):
    """Another live process is writing the run dir."""


class RunDirUnwritable(RuntimeError):
    """The run dir cannot be created or written (a file in the way, permissions, a read-only mount, a full disk)."""


@contextlib.contextmanager
def hold(run_dir: Path):
    """This process is the run dir's one writer while inside (re-entrant); raises RunDirInUse if another is."""
    run_dir = Path(run_dir).absolute()
    if run_dir in _held:
        _held[run_dir][1] += 1
    else:
        _held[run_dir] = [_acquire(run_dir), 1]
    try:
        yield
    finally:
        _held[run_dir][1] -= 1
        if _held[run_dir][1] == 0:
            os.close(_held.pop(run_dir)[0])  # closing the fd releases the flock


def _acquire(run_dir: Path) -> int:
    lock = run_dir / LOCK_FILE
    try:
        run_dir.mkdir(parents=True, exist_ok=True)
        fd = os.open(lock, os.O_CREAT | os.O_RDWR, 0o644)
    except OSError as error:
        raise RunDirUnwritable(f"run dir {run_dir} cannot be written: {error.strerror or error}") from None
    try:
        fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        holder = os.read(fd, 4096).decode(errors="replace")
        os.close(fd)
        raise RunDirInUse(f"run dir {run_dir} is being written by another process ({_describe(holder)}); "
                          "wait for it to end or stop it first") from None
    holder = {"pid": os.getpid(), "host": socket.gethostname(), "since": time.strftime("%Y-%m-%d %H:%M:%S"),
              "command": " ".join(sys.argv)[:200]}
    try:
        os.ftruncate(fd, 0)
        os.pwrite(fd, json.dumps(holder).encode(), 0)
    except OSError as error:  # a full disk: no half-named lock left behind (it is ours: we hold the flock)
        os.close(fd)
        with contextlib.suppress(OSError):
            lock.unlink()
        raise RunDirUnwritable(f"run dir {run_dir} cannot be written: {error.strerror or error}") from None
    return fd


def _describe(holder_text: str) -> str:
    try:
        holder = json.loads(holder_text)
        return f"pid {holder['pid']} on {holder['host']} since {holder['since']}: {holder['command']}"
    except (ValueError, KeyError, TypeError):
        return "its holder did not say who it is"
