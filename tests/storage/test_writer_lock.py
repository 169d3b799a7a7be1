"""One writer per run dir: a second process is refused in one line and writes nothing; a dead holder blocks
nothing."""

import json
import os
import signal
import subprocess
import sys

import pytest

from pizero_ray.cli import main
from pizero_ray.config import build_config
from pizero_ray.storage import run_dir, writer_lock

_HOLDER = """
import sys, time
from pathlib import Path
from pizero_ray.storage import writer_lock
with writer_lock.hold(Path(sys.argv[1])):
    print("holding", flush=True)
    time.sleep(600)
"""


@pytest.fixture
def holder(tmp_path):
    """Another process holding tmp_path's writer lock, as a `pizero train` under way would."""
    process = subprocess.Popen([sys.executable, "-c", _HOLDER, str(tmp_path)], stdout=subprocess.PIPE, text=True)
    assert process.stdout.readline().strip() == "holding"
    yield process
    process.kill()
    process.wait()


def _files(path):
    return {p.name: p.read_bytes() for p in sorted(path.iterdir()) if p.is_file()}


def test_a_resume_while_another_process_writes_the_run_is_refused_and_writes_nothing(tmp_path, holder, capsys):
    run_dir.write_config(tmp_path, build_config("tiny"))
    before = _files(tmp_path)
    code = main(["resume", str(tmp_path), "--iterations", "3", "--eval-every", "5", "--no-progress"])
    errors = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(errors) == 1
    assert errors[0].startswith(f"pizero: error: run dir {tmp_path} is being written by another process "
                                f"(pid {holder.pid} on ")
    assert _files(tmp_path) == before  # not even the evaluation schedule


def test_a_lock_left_by_a_killed_process_blocks_nothing(tmp_path, holder):
    holder.send_signal(signal.SIGKILL)
    holder.wait()
    assert json.loads((tmp_path / writer_lock.LOCK_FILE).read_text())["pid"] == holder.pid  # its file is left
    with writer_lock.hold(tmp_path):
        assert json.loads((tmp_path / writer_lock.LOCK_FILE).read_text())["pid"] == os.getpid()


def test_the_holder_may_take_its_lock_again_and_frees_it_when_done(tmp_path):
    with writer_lock.hold(tmp_path):
        with writer_lock.hold(tmp_path):  # the CLI holds it around the driver, which takes it too
            pass
        probe = subprocess.run([sys.executable, "-c", _HOLDER.replace("time.sleep(600)", "pass"), str(tmp_path)],
                               capture_output=True, text=True)
        assert probe.returncode != 0 and "RunDirInUse" in probe.stderr  # still held after the inner hold
    probe = subprocess.run([sys.executable, "-c", _HOLDER.replace("time.sleep(600)", "pass"), str(tmp_path)],
                           capture_output=True, text=True)
    assert probe.returncode == 0 and probe.stdout.strip() == "holding"
