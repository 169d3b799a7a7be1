"""The driver dies or is stopped, checkpoints get damaged: resume gives the same parameters."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from pizero_ray import methods
from pizero_ray.cli import main
from pizero_ray.config import build_config
from pizero_ray.storage import checkpoints, run_dir
from pizero_ray.trainer import driver

ITERATIONS = 12
# Big enough that an iteration takes a noticeable moment, so the driver can be hit mid-run. What is checked
# here is the run dir: checkpoints hold the flat parameters, whatever the agent and however many workers
# scored them. So no planner, and one worker per run: each worker (and the driver) traces and compiles the
# agent at start-up, a third of the work without the search.
WORKERS = "1"
CONFIG = build_config("tiny", population=64, chunk_size=8, planner="none")
TRAIN_ARGS = ["--preset", "tiny", "--population", "64", "--chunk-size", "8", "--planner", "none",
              "--checkpoint-every", "3", "--workers", WORKERS, "--no-progress"]


@pytest.fixture(scope="module")
def reference(ray_session, tmp_path_factory, compile_cache_dir):
    """An uninterrupted run: its directory and final parameter hash."""
    path = tmp_path_factory.mktemp("uninterrupted")
    run_dir.write_config(path, CONFIG)
    options = driver.RunOptions.create(iterations=ITERATIONS, workers=int(WORKERS), checkpoint_every=3,
                                       compile_cache=compile_cache_dir)
    return path, driver.train(path, CONFIG, options)["parameter_hash"]


def _pizero(args, cluster, cache, **kwargs):
    """`pizero ...` in a subprocess that joins the test session's cluster."""
    env = {**os.environ, "RAY_ADDRESS": cluster.address, "JAX_PLATFORMS": "cpu"}
    command = [sys.executable, "-m", "pizero_ray.cli", *args, "--compile-cache", cache]
    return subprocess.Popen(command, env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, **kwargs)


def _wait_for_rows(path: Path, rows: int, process, timeout_s: float = 300, replacing: int | None = None):
    """Until the run has ``rows`` metrics rows; with ``replacing``, an inode of metrics.jsonl, only rows in a
    file that a resume's cut has since rewritten count (the killed run's rows stay until then)."""
    deadline = time.time() + timeout_s
    metrics = path / run_dir.METRICS_FILE
    while time.time() < deadline:
        rewritten = replacing is None or metrics.stat().st_ino != replacing
        if rewritten and len(run_dir.read_metrics(path)) >= rows:
            return
        assert process.poll() is None, process.communicate()
        time.sleep(0.02)
    raise AssertionError(f"{path} never reached {rows} metrics rows")


def _resume(path, cache, capsys):
    """`pizero resume` in this process, a new driver on the session's cluster (a subprocess would only add its
    start-up: importing JAX and Ray, joining the cluster)."""
    capsys.readouterr()
    code = main(["resume", str(path), "--iterations", str(ITERATIONS), "--workers", WORKERS, "--compile-cache", cache])
    out, err = capsys.readouterr()
    assert code == 0, err
    return json.loads(out.strip().splitlines()[-1])


def _iterations(path):
    return [row["iteration"] for row in run_dir.read_metrics(path)]


def test_a_run_sigkilled_then_stopped_by_sigterm_resumes_to_the_uninterrupted_parameters(
        tmp_path, ray_cluster, compile_cache_dir, reference, capsys):
    """One run, interrupted twice (one story, so that the suite starts two drivers fewer).

    First a SIGKILL mid-run, with rows written but no periodic checkpoint yet, what a KubeRay retry meets:
    the checkpoint saved before the first iteration is there, and the cut rows are kept aside. Then the
    resumed run is stopped by SIGTERM, what `ray job stop` sends first: it saves the iteration it reached
    and says how to go on. Resumed again, it ends with the uninterrupted run's parameters."""
    path = tmp_path / "run"
    args = [arg if arg != "3" else "100" for arg in TRAIN_ARGS]  # --checkpoint-every 100
    process = _pizero(["train", "--run-dir", str(path), "--iterations", str(ITERATIONS), *args],
                      ray_cluster, compile_cache_dir)
    _wait_for_rows(path, 3, process)
    process.kill()  # SIGKILL: no handler runs, no emergency save
    process.wait()
    assert checkpoints.checkpoint_steps(path) == [0]

    killed_metrics = (path / run_dir.METRICS_FILE).stat().st_ino
    process = _pizero(["resume", str(path), "--iterations", str(ITERATIONS), "--workers", WORKERS],
                      ray_cluster, compile_cache_dir)
    _wait_for_rows(path, 2, process, replacing=killed_metrics)
    process.send_signal(signal.SIGTERM)
    _, err = process.communicate(timeout=60)
    assert process.returncode == 128 + signal.SIGTERM
    assert "pizero resume" in err
    done = _iterations(path)
    assert checkpoints.checkpoint_steps(path)[-1] == done[-1]  # the emergency save holds the last iteration
    assert done[-1] < ITERATIONS

    result = _resume(path, compile_cache_dir, capsys)
    assert result["iteration"] == ITERATIONS
    assert result["parameter_hash"] == reference[1]
    assert _iterations(path) == list(range(1, ITERATIONS + 1))  # no duplicate, no missing iteration
    assert [record["row"]["iteration"] for record in _dropped(path)][:3] == [1, 2, 3]  # the cut rows are kept


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

    result = _resume(path, compile_cache_dir, capsys)
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


def _copy_of_reference(tmp_path, reference) -> Path:
    import shutil

    path = tmp_path / "run"
    shutil.copytree(reference[0], path)
    assert checkpoints.checkpoint_steps(path) == [6, 9, 12]
    return path


def _templates():
    """The run's initial parameters and optimiser state: what a resume restores into."""
    import numpy as np

    from pizero_ray import envs

    env = envs.make(CONFIG.env, **CONFIG.env_kwargs())
    state, _, _ = methods.initial_state(CONFIG, env)
    return np.asarray(state.theta), state.carried


def _dropped(path):
    return [json.loads(line) for line in (path / run_dir.DROPPED_METRICS_FILE).read_text().splitlines()]


def test_a_restore_error_that_is_not_damage_changes_nothing(tmp_path, reference, monkeypatch, capsys):
    import orbax.checkpoint as ocp

    path = _copy_of_reference(tmp_path, reference)
    metrics = (path / "metrics.jsonl").read_text()

    def transient(self, *args, **kwargs):
        raise OSError("transient")

    monkeypatch.setattr(ocp.CheckpointManager, "restore", transient)
    newest = path / "checkpoints" / "12"
    for argv in (["resume", str(path), "--iterations", "20"], ["inspect", str(path)]):
        assert main(argv) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert err[-1] == (f"pizero: error: cannot restore checkpoint {newest}: OSError: transient; "
                           "not treated as corrupt because its files are as saved")
        assert not any("moved" in line or "previous checkpoint" in line for line in err)  # no fallback to 9
    assert checkpoints.checkpoint_steps(path) == [6, 9, 12]
    assert not (path / "checkpoints-corrupt").exists()
    assert (path / "metrics.jsonl").read_text() == metrics
    assert not (path / run_dir.DROPPED_METRICS_FILE).exists()


@pytest.mark.parametrize("change", ["optimizer structure", "parameter dtype"])
def test_a_changed_state_layout_is_not_taken_for_corruption(tmp_path, reference, change):
    """What an optax or Orbax upgrade can do: the files are intact, the restore still fails."""
    import jax.numpy as jnp
    import numpy as np
    import optax

    path = _copy_of_reference(tmp_path, reference)
    metrics = (path / "metrics.jsonl").read_text()
    theta, opt_state = _templates()
    if change == "optimizer structure":
        opt_state = optax.sgd(0.1, momentum=0.9).init(jnp.asarray(theta))
        expected = "cannot restore checkpoint .*/checkpoints/12: .*its files are as saved"
    else:  # restored with a cast: contents differ from the hash, files do not
        theta = theta.astype(np.float64)
        expected = "checkpoint .*/checkpoints/12 restored to contents that do not match its hash, but its files are"
    with pytest.raises(checkpoints.CheckpointError, match=expected):
        checkpoints.prepare_resume(path, theta, opt_state)
    assert checkpoints.checkpoint_steps(path) == [6, 9, 12]
    assert not (path / "checkpoints-corrupt").exists()
    assert (path / "metrics.jsonl").read_text() == metrics


def test_a_second_resume_after_a_full_quarantine_refuses_and_restart_keeps_the_rows(
        tmp_path, reference, compile_cache_dir, capsys):
    path = _copy_of_reference(tmp_path, reference)
    metrics = (path / "metrics.jsonl").read_text()
    for step in (6, 9, 12):
        for meta in (path / "checkpoints" / str(step) / "meta").rglob("metadata"):
            meta.write_text("{not json")
    assert main(["resume", str(path), "--iterations", "20"]) == 2
    assert "no readable checkpoint" in capsys.readouterr().err.strip().splitlines()[-1]
    assert len(list((path / "checkpoints-corrupt").iterdir())) == 3

    assert main(["resume", str(path), "--iterations", "20"]) == 2  # what a KubeRay retry does next
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1] == (f"pizero: error: run dir {path} holds 3 quarantined checkpoints in "
                       f"{path / 'checkpoints-corrupt'} and 12 metrics rows but no checkpoint to continue from; "
                       "to start again from iteration 0, keeping what it replaces, add --restart")
    assert (path / "metrics.jsonl").read_text() == metrics

    assert main(["resume", str(path), "--iterations", "2", "--restart", "--workers", WORKERS, "--no-progress",
                 "--compile-cache", compile_cache_dir]) == 0
    assert _iterations(path) == [1, 2]
    dropped = _dropped(path)
    assert [record["row"] for record in dropped] == [json.loads(line) for line in metrics.splitlines()]
    assert all(record["dropped_at"] and "--restart" in record["reason"] for record in dropped)
    (replaced,) = (path / "replaced").iterdir()
    assert len(list((replaced / "checkpoints-corrupt").iterdir())) == 3  # set aside, not deleted
    assert not (path / "checkpoints-corrupt").exists()
    assert checkpoints.checkpoint_steps(path) == [0, 2]


def test_metrics_are_cut_to_the_newest_checkpoint_and_the_rest_kept(tmp_path, reference):
    path = _copy_of_reference(tmp_path, reference)
    rows = run_dir.read_metrics(path)
    # What a driver SIGKILLed during iteration 15 leaves: rows past the newest checkpoint, the last one cut short.
    extra = [{**rows[-1], "iteration": 13}, {**rows[-1], "iteration": 14}]
    with open(path / "metrics.jsonl", "a") as file:
        file.write("".join(json.dumps(row) + "\n" for row in extra) + '{"iteration": 15, "mean_sc')
    resumed = checkpoints.prepare_resume(path, *_templates())
    assert resumed.iteration == 12
    assert run_dir.read_metrics(path) == resumed.metrics == rows  # nothing at or below the checkpoint is cut
    dropped = _dropped(path)
    assert [record.get("row") for record in dropped[:2]] == extra
    assert dropped[2]["unreadable_line"] == '{"iteration": 15, "mean_sc'


@pytest.mark.parametrize("damage", ["truncate", "delete"])
def test_a_truncated_or_deleted_file_is_corrupt_and_the_previous_checkpoint_is_used(tmp_path, reference, capsys,
                                                                                    damage):
    path = _copy_of_reference(tmp_path, reference)
    data = _newest_step_data(path)
    if damage == "truncate":
        data.write_bytes(data.read_bytes()[: data.stat().st_size // 2])
    else:
        data.unlink()
    resumed = checkpoints.prepare_resume(path, *_templates())
    assert resumed.iteration == 9
    name = data.relative_to(path / "checkpoints" / "12").as_posix()
    assert f"checkpoint {path / 'checkpoints' / '12'} is corrupt: {name} is " in capsys.readouterr().err
    assert checkpoints.checkpoint_steps(path) == [6, 9]
    assert [p.name.split("-")[0] for p in (path / "checkpoints-corrupt").iterdir()] == ["12"]
    assert _iterations(path) == list(range(1, 10))
    assert [record["row"]["iteration"] for record in _dropped(path)] == [10, 11, 12]


@pytest.mark.parametrize("damage, corrupt", [("remove state", True), ("empty a file", True), ("truncate", False)])
def test_a_checkpoint_without_a_manifest_is_corrupt_only_when_visibly_broken(tmp_path, reference, damage, corrupt):
    """Older checkpoints have no manifest: a missing item or an empty file shows damage, a short file does not."""
    import shutil

    path = _copy_of_reference(tmp_path, reference)
    newest = path / "checkpoints" / "12"
    (newest / checkpoints.MANIFEST_FILE).unlink()
    data = _newest_step_data(path)
    if damage == "remove state":
        shutil.rmtree(newest / "state")
    else:
        data.write_bytes(b"" if damage == "empty a file" else data.read_bytes()[: data.stat().st_size // 2])
    if corrupt:
        assert checkpoints.prepare_resume(path, *_templates()).iteration == 9
        assert checkpoints.checkpoint_steps(path) == [6, 9]
    else:
        with pytest.raises(checkpoints.CheckpointError, match="no file manifest and its files look complete"):
            checkpoints.prepare_resume(path, *_templates())
        assert checkpoints.checkpoint_steps(path) == [6, 9, 12]


def test_a_decaying_step_size_resumes_where_its_schedule_stood(tmp_path):
    """The schedule's step count is optimiser state: saved, restored, and the next step is the uninterrupted one."""
    import jax.numpy as jnp
    import numpy as np

    from pizero_ray import es

    optimizer = es.make_optimizer(build_config("tiny", lr_decay_iterations=4))
    theta, gradient = jnp.zeros(5), jnp.linspace(-1.0, 1.0, 5)
    state = optimizer.init(theta)
    for _ in range(2):
        _, state = optimizer.update(gradient, state, theta)
    writer = checkpoints.CheckpointWriter(tmp_path)
    writer.save(2, np.asarray(theta), state, {})
    writer.close()
    restored = checkpoints.restore_latest(tmp_path, np.asarray(theta), optimizer.init(theta))
    assert restored.iteration == 2
    after_resume, _ = optimizer.update(gradient, restored.carried, theta)
    uninterrupted, _ = optimizer.update(gradient, state, theta)
    np.testing.assert_array_equal(np.asarray(after_resume), np.asarray(uninterrupted))
    assert 0.0 < float(jnp.linalg.norm(after_resume)) < float(jnp.linalg.norm(optimizer.update(
        gradient, optimizer.init(theta), theta)[0]))  # the third step, smaller than the first
