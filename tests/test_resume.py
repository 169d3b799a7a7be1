"""The driver dies or is stopped, checkpoints get damaged: resume gives the same parameters."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from pizero_ray import checkpoints, driver, run_dir
from pizero_ray.cli import main
from pizero_ray.config import build_config

ITERATIONS = 12
# Big enough that an iteration takes a noticeable moment, so the driver can be hit mid-run.
CONFIG = build_config("tiny", population=64, chunk_size=8)
TRAIN_ARGS = ["--preset", "tiny", "--population", "64", "--chunk-size", "8", "--checkpoint-every", "3",
              "--workers", "2", "--no-progress"]


@pytest.fixture(scope="module")
def reference(ray_session, tmp_path_factory, compile_cache_dir):
    """An uninterrupted run: its directory and final parameter hash."""
    path = tmp_path_factory.mktemp("uninterrupted")
    run_dir.write_config(path, CONFIG)
    options = driver.RunOptions(iterations=ITERATIONS, workers=2, checkpoint_every=3, compile_cache=compile_cache_dir)
    return path, driver.train(path, CONFIG, options)["parameter_hash"]


def _pizero(args, cluster, cache, **kwargs):
    """`pizero ...` in a subprocess that joins the test session's cluster."""
    env = {**os.environ, "RAY_ADDRESS": cluster.address, "JAX_PLATFORMS": "cpu"}
    command = [sys.executable, "-m", "pizero_ray.cli", *args, "--compile-cache", cache]
    return subprocess.Popen(command, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kwargs)


def _wait_for_rows(path: Path, rows: int, process, timeout_s: float = 300):
    deadline = time.time() + timeout_s
    while time.time() < deadline:
        if len(run_dir.read_metrics(path)) >= rows:
            return
        assert process.poll() is None, process.communicate()
        time.sleep(0.02)
    raise AssertionError(f"{path} never reached {rows} metrics rows")


def _resume(path, cluster, cache):
    process = _pizero(["resume", str(path), "--iterations", str(ITERATIONS), "--workers", "2"], cluster, cache)
    out, err = process.communicate(timeout=600)
    assert process.returncode == 0, err
    return json.loads(out.strip().splitlines()[-1])


def _iterations(path):
    return [row["iteration"] for row in run_dir.read_metrics(path)]


def test_driver_sigkilled_mid_run_then_resumed(tmp_path, ray_cluster, compile_cache_dir, reference):
    path = tmp_path / "run"
    process = _pizero(["train", "--run-dir", str(path), "--iterations", str(ITERATIONS), *TRAIN_ARGS],
                      ray_cluster, compile_cache_dir)
    _wait_for_rows(path, 5, process)
    process.kill()  # SIGKILL: no handler runs, no emergency save
    process.wait()
    assert 3 <= checkpoints.checkpoint_steps(path)[-1] < ITERATIONS
    result = _resume(path, ray_cluster, compile_cache_dir)
    assert result["iteration"] == ITERATIONS
    assert result["parameter_hash"] == reference[1]
    assert _iterations(path) == list(range(1, ITERATIONS + 1))  # no duplicate, no missing iteration


def test_sigterm_saves_a_checkpoint_and_resume_matches(tmp_path, ray_cluster, compile_cache_dir, reference):
    path = tmp_path / "run"
    process = _pizero(["train", "--run-dir", str(path), "--iterations", str(ITERATIONS), *TRAIN_ARGS],
                      ray_cluster, compile_cache_dir)
    _wait_for_rows(path, 4, process)
    process.send_signal(signal.SIGTERM)  # what `ray job stop` sends first
    _, err = process.communicate(timeout=60)
    assert process.returncode == 128 + signal.SIGTERM
    assert "pizero resume" in err
    done = _iterations(path)
    assert checkpoints.checkpoint_steps(path)[-1] == done[-1]  # the emergency save holds the last iteration
    assert done[-1] < ITERATIONS
    result = _resume(path, ray_cluster, compile_cache_dir)
    assert result["parameter_hash"] == reference[1]
    assert _iterations(path) == list(range(1, ITERATIONS + 1))


def _newest_step_data(path: Path) -> Path:
    step_dir = path / "checkpoints" / str(checkpoints.checkpoint_steps(path)[-1]) / "state"
    return max((p for p in step_dir.rglob("*") if p.is_file()), key=lambda p: p.stat().st_size)


def test_truncated_checkpoint_falls_back_to_the_previous_one(tmp_path, ray_cluster, compile_cache_dir, reference,
                                                             capsys):
    import shutil

    path = tmp_path / "run"
    shutil.copytree(reference[0], path)
    assert checkpoints.checkpoint_steps(path) == [6, 9, 12]
    data = _newest_step_data(path)
    data.write_bytes(data.read_bytes()[: data.stat().st_size // 2])  # cut the newest checkpoint short

    assert main(["inspect", str(path), "--json"]) == 0
    captured = capsys.readouterr()
    assert json.loads(captured.out)["iteration"] == 9
    assert str(path / "checkpoints" / "12") in captured.err  # the bad checkpoint is named

    result = _resume(path, ray_cluster, compile_cache_dir)
    assert result["parameter_hash"] == reference[1]
    assert len(list((path / "checkpoints-corrupt").iterdir())) == 1  # kept aside, not deleted
    assert checkpoints.checkpoint_steps(path)[-1] == ITERATIONS


def test_unfinished_save_is_never_taken_for_a_checkpoint(tmp_path, reference, capsys):
    import shutil

    path = tmp_path / "run"
    shutil.copytree(reference[0], path)
    # What a process killed during a save leaves behind: Orbax's temporary directory.
    partial = path / "checkpoints" / "15.orbax-checkpoint-tmp-1234"
    shutil.copytree(path / "checkpoints" / "12", partial)
    assert checkpoints.checkpoint_steps(path) == [6, 9, 12]
    assert main(["inspect", str(path), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["iteration"] == 12


def test_all_checkpoints_corrupt_is_a_clear_error(tmp_path, reference, capsys):
    import shutil

    path = tmp_path / "run"
    shutil.copytree(reference[0], path)
    for step in checkpoints.checkpoint_steps(path):
        for meta in (path / "checkpoints" / str(step) / "meta").rglob("metadata"):
            meta.write_text("{not json")
    assert main(["resume", str(path), "--iterations", "20"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1].startswith("pizero: error: no readable checkpoint in")
    assert (path / "metrics.jsonl").read_text() == (reference[0] / "metrics.jsonl").read_text()  # nothing lost
