"""`pizero experiment` end to end: a 2x2 grid on Ray Tune, killed mid-way and restored; then plot-experiment.

The experiment runs as a `pizero` subprocess in its own process group with
its own local Ray instance (as a user runs it), so that it can be SIGKILLed
whole, Ray included, and started again with the same command.
"""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from pizero_ray.experiment import grid
from tests.figures import assert_curves_drawn, colourful_pixels, columns, read_rgb

pytestmark = pytest.mark.slow  # minutes: four trials' start-ups and compiles, twice a Ray instance

BUDGET_MINUTES, EVAL_EVERY_MINUTES = 0.04, 0.02  # 2.4 s of training per run, evaluated at 0, 1.2 s and the end
# One seed: two environments (the sittings test joins them) and both kinds of trainer (an ES trial's workers, a
# baseline learning in its trial's process) are what a restore must handle; more seeds only add start-ups.
ENVS, METHODS, SEEDS = ("tsp", "collect"), ("es", "alphazero"), 1
TRIALS = grid.Experiment(envs=ENVS, methods=METHODS, seeds=SEEDS, budget_minutes=BUDGET_MINUTES,
                         eval_every_minutes=EVAL_EVERY_MINUTES).trials
GRID = ["--envs", ",".join(ENVS), "--methods", ",".join(METHODS), "--seeds", str(SEEDS), "--budget-minutes",
        str(BUDGET_MINUTES), "--eval-every-minutes", str(EVAL_EVERY_MINUTES), "--eval-episodes", "8",
        "--cpus-per-trial", "1", "--preset", "tiny", "--selfplay-episodes", "4", "--batch-size", "16",
        "--replay-size", "8", "--updates-per-iteration", "2"]


def _command(out: Path, cache: str) -> list[str]:
    return [sys.executable, "-m", "pizero_ray.cli", "experiment", *GRID, "--out", str(out), "--compile-cache", cache]


def _finished(out: Path) -> dict[str, list[dict]]:
    """Trial name -> metrics rows, for the runs that have ended: a last row past the budget, evaluated,
    and the final checkpoint saved at it. (Killed between that row and that save, a run resumes from its
    previous checkpoint and trains the dropped iterations again, as it should: it had not finished.)"""
    from pizero_ray.storage import checkpoints, run_dir

    done = {}
    for trial in TRIALS:
        path = grid.run_path(out, trial)
        rows = run_dir.read_metrics(path)  # a row being written is left out
        if rows and "eval_mean_score" in rows[-1] and rows[-1]["wall_time_s"] >= 60 * BUDGET_MINUTES:
            if checkpoints.checkpoint_steps(path)[-1:] == [rows[-1]["iteration"]]:
                done[trial.name] = rows
    return done


def _states(out: Path) -> dict[str, str]:
    """Each trial's last metrics rows and checkpoint steps: what a failure report needs to be read."""
    from pizero_ray.storage import checkpoints, run_dir

    states = {}
    for trial in TRIALS:
        path = grid.run_path(out, trial)
        rows = [{key: row.get(key) for key in ("iteration", "wall_time_s", "eval_mean_score")}
                for row in run_dir.read_metrics(path)[-2:]]
        steps = checkpoints.checkpoint_steps(path) if path.exists() else []
        states[trial.name] = f"last rows {rows}; checkpoints {steps}"
    return states


@pytest.fixture(scope="module")
def experiment(tmp_path_factory, compile_cache_dir):
    """The grid started, SIGKILLed (Ray and all) once a trial has finished, and run again to its end."""
    out = tmp_path_factory.mktemp("experiment")
    env = {k: v for k, v in os.environ.items() if k != "RAY_ADDRESS"}
    first = subprocess.Popen(_command(out, compile_cache_dir), env=env, start_new_session=True,
                             stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    deadline = time.time() + 400
    while not _finished(out) and first.poll() is None and time.time() < deadline:
        time.sleep(0.2)
    os.killpg(first.pid, signal.SIGKILL)
    first.wait()
    before = _finished(out)
    second = subprocess.run(_command(out, compile_cache_dir), env=env, capture_output=True, text=True, timeout=500)
    return out, before, second


def test_a_killed_experiment_is_restored_and_finishes_without_rerunning_finished_trials(experiment):
    out, before, second = experiment
    assert 1 <= len(before) < len(TRIALS)  # the kill fell mid-way
    assert second.returncode == 0, second.stderr[-3000:]
    summary = json.loads(second.stdout.strip().splitlines()[-1])
    assert summary["finished"] == len(TRIALS) and not summary["errors"], (summary, second.stderr[-3000:], _states(out))
    after = _finished(out)
    assert sorted(after) == sorted(t.name for t in grid.read_spec(out).trials)
    for name, rows in before.items():
        assert after[name] == rows  # finished before the kill: not trained again
    for rows in after.values():
        iterations = [row["iteration"] for row in rows]
        assert iterations == sorted(set(iterations))  # a resumed trial has each iteration once
    assert summary == json.loads((out / "summary.json").read_text())
    trial_dirs = [path for path in (out / "tune").iterdir() if path.is_dir()]
    assert len(trial_dirs) == len(TRIALS)  # Tune's own trials: restored, not duplicated
    assert all((grid.run_path(out, t) / "tensorboard").is_dir() for t in grid.read_spec(out).trials)


def test_plot_experiment_writes_both_figures_and_a_table_row_per_env_and_method(experiment, tmp_path, capsys):
    from pizero_ray.cli import main

    out = experiment[0]
    assert main(["plot-experiment", str(out), "--out", str(tmp_path / "docs")]) == 0
    report = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert report["results"] == 4 and report["states"] == ["collect", "tsp"]
    # One panel per environment (TSP, Collect), 4.6 x 3.8 inches at 110 dpi, each with a curve per method: es in
    # C0, alphazero in C1, drawn over it. Collect's scores are whole coins averaged over 8 episodes, so the two
    # curves may tie there and es's lie hidden: only alphazero's is sure to show.
    assert_curves_drawn(tmp_path / "docs" / "results.png", size=(1012, 418), panels=[("C0", "C1"), ("C1",)])
    # One final state per environment, side by side, 4 x 4.8 inches each at 150 dpi. The environments draw in
    # colour (TSP's tour, Collect's agent and coins); the titles and notes around them are black on white.
    states = read_rgb(tmp_path / "docs" / "states.png")
    assert states.shape[:2] == (720, 1200)
    drawn = [colourful_pixels(panel) for panel in columns(states, 2)]
    assert all(count >= 1000 for count in drawn), drawn
    table = (tmp_path / "docs" / "results_table.md").read_text()
    for env in ("tsp", "collect"):
        for method in ("es", "alphazero"):
            assert sum(line.startswith(f"| {env} | {method} |") for line in table.splitlines()) == 1
    results = json.loads((tmp_path / "docs" / "results.json").read_text())
    assert {row["seeds"] for row in results["results"]} == {SEEDS}
    assert {"random", "nearest_neighbour", "optimal"} <= set(results["references"]["tsp"])
    assert {"random", "greedy"} <= set(results["references"]["collect"])
    for row in results["results"]:
        low, high = row["ci95_bca"]
        assert low <= row["mean_score"] <= high


def test_plot_experiment_joins_sittings_over_other_environments(experiment, tmp_path, capsys):
    """The grid's two environments as two sittings (copies of its run dirs, one spec each): one table, one figure."""
    import dataclasses
    import shutil

    from pizero_ray.cli import main
    from pizero_ray.experiment.results import REFERENCES_FILE

    out = experiment[0]
    spec = grid.read_spec(out)
    sittings = []
    for env in spec.envs:
        sitting = tmp_path / f"sitting-{env}"
        shutil.copytree(out / grid.RUNS / env, sitting / grid.RUNS / env)
        if (out / REFERENCES_FILE).exists():  # scored by the test above: not scored again
            shutil.copy(out / REFERENCES_FILE, sitting / REFERENCES_FILE)
        grid.write_spec(sitting, dataclasses.replace(
            spec, envs=(env,), env_args=tuple(item for item in spec.env_args if item[0] == env),
            eval_env_args=tuple(item for item in spec.eval_env_args if item[0] == env)))
        sittings.append(str(sitting))
    assert main(["plot-experiment", *sittings, "--out", str(tmp_path / "docs")]) == 0
    shown = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert shown["results"] == 4 and shown["states"] == ["collect", "tsp"]
    joined = json.loads((tmp_path / "docs" / "results.json").read_text())
    assert [(row["env"], row["method"]) for row in joined["results"]] == [
        (env, method) for env in spec.envs for method in spec.methods]
    assert set(joined["references"]) == set(spec.envs)
