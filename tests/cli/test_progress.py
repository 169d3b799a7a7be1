"""What training and the other commands say while they work: the first iteration's note, the time left, the
summary before the JSON line, and where a resumed run stands."""

import json

from pizero_ray.cli import main, progress
from pizero_ray.config import build_config
from pizero_ray.storage import run_dir
from pizero_ray.trainer.options import RunOptions


def test_the_first_iteration_is_announced_as_slow_before_it_starts(capsys):
    on_start, on_iteration, close = progress.progress_callbacks(RunOptions.create(minutes=2.0), no_progress=True)
    on_start({"connection": "local Ray instance", "workers": 2, "parameters": 10, "start_iteration": 0})
    on_iteration({"iteration": 1, "mean_score": -1.0, "iteration_time_s": 30.0, "wall_time_s": 30.0})
    close()
    err = capsys.readouterr().err.splitlines()
    assert err[0] == "pizero: local Ray instance, asking for 2 workers, 10 parameters, starting at iteration 0"
    assert err[1].startswith("pizero: the first iteration starts the workers and compiles the rollout")
    # piped, with a budget alone: the training time against the budget and what is left of it
    assert err[2].endswith("(30.00 s, 0:30 of 2:00 trained, ETA 1:30)"), err[2]


def test_the_time_left_is_the_sooner_of_the_budget_and_the_iterations_at_this_pace():
    remaining = progress._Remaining(RunOptions.create(iterations=10, minutes=60.0))
    remaining.started -= 4.0  # four seconds into this session, the first of its iterations done
    assert abs(remaining({"iteration": 1, "wall_time_s": 4.0}) - 36.0) < 0.5  # 9 more at 4 s each
    assert progress._Remaining(RunOptions.create(minutes=1.0))({"iteration": 7, "wall_time_s": 75.0}) == 0.0


def test_the_summary_says_what_this_session_trained_and_its_last_evaluation():
    seen = {"first": {"iteration": 5, "wall_time_s": 10.0},
            "last": {"iteration": 9, "wall_time_s": 130.0},
            "evaluated": {"iteration": 8, "eval_mean_score": -2.5}}
    line = progress.summary_line({"iteration": 9}, seen, RunOptions.create(minutes=5.0), 125.0)
    assert line == ("pizero: trained iterations 5-9 (5) in 2:05; 2:10 of training time in all of the 5-minute "
                    "budget; last evaluation -2.5000 at iteration 8")
    assert progress.summary_line({"iteration": 9}, {}, RunOptions.create(iterations=9), 1.0) == (
        "pizero: nothing trained: the run is at iteration 9")


def test_a_resume_with_its_budget_spent_says_so_and_starts_nothing(tmp_path, capsys):
    from tests.cli.test_run_dir_is_data import _saved_run

    run = _saved_run(tmp_path / "run", iterations=(0, 3))
    rows = [{"iteration": i, "wall_time_s": 40.0 * i, "mean_score": -1.0} for i in range(4)]
    (run / run_dir.METRICS_FILE).write_text("".join(json.dumps(row) + "\n" for row in rows))
    assert main(["resume", str(run), "--minutes", "2"]) == 0
    err = capsys.readouterr().err.strip().splitlines()
    assert err == [f"pizero: run {run} is at iteration 3, 2:00 of the 2-minute budget trained: nothing to train; "
                   "give more with --iterations or --minutes"]


def test_eval_says_what_it_plays_once_the_run_is_loaded(tmp_path, capsys):
    run_dir.write_config(tmp_path, build_config("tiny", planner="none"))
    assert main(["eval", str(tmp_path), "--episodes", "2", "--json"]) == 0
    err = capsys.readouterr().err.splitlines()
    assert err[0].startswith("pizero eval: playing 2 episodes") and err[1].startswith("pizero eval: done in ")
