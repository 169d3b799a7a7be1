"""A run dir is data: reading one runs no code it names, a run never mixes two configurations, and each way a
run dir or an option can be wrong is one line on stderr. None of these tests starts Ray: every refusal comes
before it would."""

import errno
import json
import os

import pytest

from pizero_ray import methods
from pizero_ray.cli import main
from pizero_ray.config import build_config
from pizero_ray.storage import checkpoints, run_dir, runs, writer_lock

TINY = build_config("tiny", population=16, chunk_size=8, planner="none")


def _run(argv, capsys):
    try:
        code = main(argv)
    except SystemExit as exit_:  # argparse's own errors
        code = exit_.code
    return code, capsys.readouterr().err.strip().splitlines()


def _saved_run(path, config=TINY, iterations=(0,)):
    """A run dir as training leaves it: config.json, the schedule, and checkpoints at ``iterations`` (no Ray)."""
    run_dir.write_config(path, config)
    run_dir.write_schedule(path, {"eval_every": 0, "checkpoint_every": 1})
    state, _, _ = methods.initial_state(config, methods.make_env(config))
    writer = checkpoints.CheckpointWriter(path)
    for iteration in iterations:
        runs.save(writer, config, state._replace(iteration=iteration))
    writer.close()
    return path


# ---------------------------------------------------------------- a run dir's environment is data


def _malicious(path, marker):
    """config.json naming os:system, as a run dir from elsewhere could."""
    config = build_config("tiny", env="os:system", env_args={"command": f"touch {marker}"})
    run_dir.write_config(path, config)
    return path


@pytest.mark.parametrize("command", [["eval"], ["inspect"], ["render", "--out", "x.png"],
                                     ["resume", "--iterations", "2"], ["compare"]])
def test_a_run_dir_naming_code_runs_nothing_unless_trusted(tmp_path, capsys, command):
    marker = tmp_path / "PWNED"
    run = _malicious(tmp_path / "run", marker)
    runs_named = [str(run), str(run)] if command == ["compare"] else [str(run)]
    code, err = _run([command[0], *runs_named, *command[1:]], capsys)
    assert code == 2 and len(err) == 1, err
    assert "names its environment by import path 'os:system'" in err[0] and "--trust-env" in err[0], err
    assert not marker.exists()


def test_naming_the_environment_again_trusts_it(tmp_path, capsys):
    marker = tmp_path / "PWNED"
    run = _malicious(tmp_path / "run", marker)
    code, err = _run(["inspect", str(run), "--env", "os:system"], capsys)
    assert marker.exists()  # trusted on purpose: the module's code ran (os.system returns no Environment)
    assert code == 2 and len(err) == 1 and "must return a pizero_ray.envs.base.Environment" in err[0], err


def test_naming_another_environment_is_refused(tmp_path, capsys):
    run = _malicious(tmp_path / "run", tmp_path / "PWNED")
    code, err = _run(["eval", str(run), "--env", "examples.corridor:make"], capsys)
    assert code == 2 and len(err) == 1 and "is not the environment of run dir" in err[0], err
    assert not (tmp_path / "PWNED").exists()


def test_an_experiment_naming_code_is_refused_by_plot_experiment(tmp_path, capsys):
    from pizero_ray.experiment import grid

    spec = {"envs": ["os:system"], "methods": ["es"], "seeds": 1, "budget_minutes": 1.0, "eval_every_minutes": 1.0,
            "eval_episodes": 8, "cpus_per_trial": 1, "preset": "tiny", "overrides": [], "env_args": [],
            "eval_env_args": []}
    (tmp_path / grid.SPEC_FILE).write_text(json.dumps(spec))
    code, err = _run(["plot-experiment", str(tmp_path), "--out", str(tmp_path / "report")], capsys)
    assert code == 2 and len(err) == 1 and "--trust-env" in err[0], err
    assert not (tmp_path / "report").exists()


# ---------------------------------------------------------------- one configuration per run


def test_resume_refuses_a_config_json_changed_since_the_checkpoint(tmp_path, capsys):
    run = _saved_run(tmp_path / "run")
    schedule = (run / run_dir.EVALUATION_FILE).read_text()
    changed = json.loads((run / run_dir.CONFIG_FILE).read_text())
    changed.update(population=8, learning_rate=0.5)
    (run / run_dir.CONFIG_FILE).write_text(json.dumps(changed))
    code, err = _run(["resume", str(run), "--iterations", "3", "--eval-every", "5"], capsys)
    assert code == 2 and len(err) == 1, err
    assert "population 16 (now 8)" in err[0] and "learning_rate 0.01 (now 0.5)" in err[0], err
    assert (run / run_dir.EVALUATION_FILE).read_text() == schedule  # a refused resume writes nothing


def test_settings_that_only_change_how_the_rollout_compiles_may_change(tmp_path):
    run = _saved_run(tmp_path / "run")
    runs.check_same_config(run, build_config("tiny", population=16, chunk_size=8, planner="none",
                                             episode_loop="horizon"))


def test_train_refuses_a_run_dir_with_checkpoints_but_no_config(tmp_path, capsys):
    run = _saved_run(tmp_path / "run")
    (run / run_dir.CONFIG_FILE).unlink()
    code, err = _run(["train", "--run-dir", str(run), "--preset", "tiny", "--seed", "5"], capsys)
    assert code == 2 and len(err) == 1 and "1 checkpoint" in err[0] and "no config.json" in err[0], err
    assert not (run / run_dir.CONFIG_FILE).exists()


# ---------------------------------------------------------------- one line, not a traceback


@pytest.mark.parametrize("row", ["{}", "5", '{"iteration": "x"}'])
def test_a_metrics_line_that_is_no_row_ends_the_readable_log(tmp_path, row):
    run = tmp_path
    (run / run_dir.METRICS_FILE).write_text('{"iteration": 0}\n' + row + '\n{"iteration": 2}\n')
    assert run_dir.read_metrics(run) == [{"iteration": 0}]
    assert checkpoints.held_progress(run) == []


def test_a_resume_says_when_it_moves_unreadable_metrics_lines(tmp_path, capsys):
    (tmp_path / run_dir.METRICS_FILE).write_text('{"iteration": 0}\n{"iteration": 1, "mean_sc')
    run_dir.keep_metrics_through(tmp_path, 0, "test")
    err = capsys.readouterr().err
    assert "1 unreadable line(s) from line 2 on" in err and run_dir.DROPPED_METRICS_FILE in err


@pytest.mark.parametrize("text, named", [('{"bogus": 1}', "unknown settings 'bogus'"),
                                         ("[1, 2]", "must hold a JSON object of settings, got list")])
def test_a_bad_evaluation_json_is_one_line(tmp_path, capsys, text, named):
    run = _saved_run(tmp_path / "run")
    (run / run_dir.EVALUATION_FILE).write_text(text)
    code, err = _run(["resume", str(run), "--iterations", "2"], capsys)
    assert code == 2 and len(err) == 1 and named in err[0], err


def test_a_checkpoint_that_cannot_be_saved_is_one_line(tmp_path, monkeypatch):
    writer = checkpoints.CheckpointWriter(tmp_path)
    monkeypatch.setattr(writer._manager, "save", _raises(OSError(errno.ENOSPC, "No space left on device")))
    with pytest.raises(checkpoints.CheckpointSaveError) as raised:
        writer.save(3, TINY_THETA(), (), {})
    assert "saving the checkpoint of iteration 3" in str(raised.value)
    assert "No space left on device" in str(raised.value) and "\n" not in str(raised.value)


def TINY_THETA():
    import numpy as np

    return np.zeros(4, np.float32)


def _raises(error):
    def fail(*args, **kwargs):
        raise error

    return fail


def test_a_full_disk_at_the_lock_is_one_line_and_leaves_no_lock(tmp_path, monkeypatch):
    monkeypatch.setattr(os, "pwrite", _raises(OSError(errno.ENOSPC, "No space left on device")))
    with pytest.raises(writer_lock.RunDirUnwritable) as raised:
        with writer_lock.hold(tmp_path / "run"):
            pass
    assert "No space left on device" in str(raised.value)
    assert not (tmp_path / "run" / writer_lock.LOCK_FILE).exists()


def test_a_run_dir_that_cannot_be_written_is_refused_before_anything(tmp_path, capsys, monkeypatch):
    run = _saved_run(tmp_path / "run")
    before = sorted(p.name for p in run.iterdir())
    real_access = os.access
    monkeypatch.setattr(os, "access", lambda path, mode: False if str(path) == str(run) else real_access(path, mode))
    code, err = _run(["resume", str(run), "--iterations", "2"], capsys)
    assert code == 2 and len(err) == 1 and f"run dir {run}: {run} is not writable" in err[0], err
    assert sorted(p.name for p in run.iterdir()) == before


def test_a_run_dir_under_a_file_is_one_line(tmp_path, capsys):
    (tmp_path / "a-file").write_text("")
    code, err = _run(["train", "--run-dir", str(tmp_path / "a-file" / "run"), "--preset", "tiny"], capsys)
    assert code == 2 and len(err) == 1 and "is a file, not a directory" in err[0], err


@pytest.mark.parametrize("extra, named", [
    (["--chunk-timeout", "nan"], "--chunk-timeout must be a finite number, got nan"),
    (["--cpus-per-worker", "-1"], "--cpus-per-worker must be at least 0, got -1.0"),
    (["--lr", "inf"], "--lr must be a finite number, got inf"),
    (["--sigma", "inf"], "--sigma must be a finite number, got inf"),
    (["--population", "1099511627776"], "pairs need at least"),
    (["--env-arg", "num_cities=100000000"], "GiB on the driver, more than this machine's"),
    (["--method", "alphazero", "--workers", "4"], "method alphazero trains in one process, without Ray workers"),
])
def test_bad_values_are_refused_in_one_line_before_anything_is_written(tmp_path, capsys, extra, named):
    run = tmp_path / "run"
    code, err = _run(["train", "--run-dir", str(run), "--preset", "tiny", *extra], capsys)
    assert code == 2 and len(err) == 1 and named in err[0], err
    assert not run.exists()


def test_an_environment_factory_raising_anything_is_one_line(tmp_path, capsys, monkeypatch):
    (tmp_path / "raising_env.py").write_text("def make():\n    raise RuntimeError('no GPU here\\nand more')\n")
    monkeypatch.chdir(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))
    code, err = _run(["train", "--run-dir", str(tmp_path / "run"), "--env", "raising_env:make"], capsys)
    assert code == 2 and err == ["pizero: error: environment 'raising_env:make': the factory raised RuntimeError: "
                                 "no GPU here"], err


def test_eval_refuses_a_run_whose_checkpoints_are_not_a_directory(tmp_path, capsys):
    run = _saved_run(tmp_path / "run")
    checkpoints_dir = run / checkpoints.CHECKPOINT_DIR
    checkpoints_dir.rename(tmp_path / "elsewhere")
    checkpoints_dir.write_text("")
    code, err = _run(["eval", str(run), "--episodes", "2"], capsys)
    assert code == 2 and len(err) == 1 and "is not a directory" in err[0], err


def test_eval_refuses_a_run_with_progress_but_no_checkpoint(tmp_path, capsys):
    run_dir.write_config(tmp_path, TINY)
    (tmp_path / run_dir.METRICS_FILE).write_text('{"iteration": 1}\n{"iteration": 2}\n')
    code, err = _run(["eval", str(tmp_path), "--episodes", "2"], capsys)
    assert code == 2 and len(err) == 1 and "2 metrics rows but no checkpoint" in err[0], err


def test_a_usage_error_is_one_line(tmp_path, capsys):
    code, err = _run(["train", "--run-dir", str(tmp_path), "--populaton", "3"], capsys)
    assert code == 2 and len(err) == 1 and "unrecognized arguments: --populaton 3" in err[0], err


def test_an_unforeseen_error_is_one_line_and_verbose_shows_it(tmp_path, capsys, monkeypatch):
    from pizero_ray.cli import reports

    monkeypatch.setattr(reports, "existing_run", _raises(KeyError("deep inside")))
    code, err = _run(["inspect", str(tmp_path)], capsys)
    assert code == 1 and len(err) == 1 and "KeyError: 'deep inside'" in err[0] and "--verbose" in err[0], err
    with pytest.raises(KeyError):
        main(["inspect", str(tmp_path), "--verbose"])


def test_a_population_the_chunk_does_not_divide_is_said(capsys):
    from pizero_ray.cli import training
    from pizero_ray.cli.commands import build_parser

    config = training.train_config(build_parser().parse_args(["train", "--run-dir", "x", "--population", "7"]))
    assert config.chunk_size == 7
    assert "--population 7 is no multiple of the preset's chunk of 32 pairs: chunks of 7 pairs" in \
        capsys.readouterr().err


def test_a_resume_keeps_the_checkpoint_cadence(tmp_path):
    from pizero_ray.cli import training
    from pizero_ray.cli.commands import build_parser

    run = _saved_run(tmp_path / "run")  # trained with --checkpoint-every 1
    args = build_parser().parse_args(["resume", str(run), "--iterations", "4"])
    assert training.run_options(args, 4, run_dir.read_schedule(run)).checkpoint_every == 1
