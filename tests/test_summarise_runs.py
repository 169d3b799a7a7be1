"""scripts/summarise_runs.py: the docs' JSON summaries come from run dirs and eval JSON, figures unchanged."""

import json
from pathlib import Path

import pytest

from pizero_ray.config import build_config
from pizero_ray.storage import run_dir
from tests.scripts_loading import load_script


@pytest.fixture(scope="module")
def summarise():
    return load_script("summarise_runs")


def _run(path: Path, scores: list[float], spreads: list[float] | None = None) -> None:
    run_dir.write_config(path, build_config("tiny", env="collect", planner="none", env_args={"view": "centred"}))
    spreads = spreads or [1.0] * len(scores)
    rows = [{"iteration": i, "iteration_time_s": 0.5 + i, "wall_time_s": 2.0 * i, "parameter_norm": 20.04 + i,
             "mean_score": -9.0,
             "std_score": spread, "max_score": -9.0 + spread,
             **({"eval_mean_score": score} if score is not None else {})}
            for i, (score, spread) in enumerate(zip(scores, spreads), 1)]
    untrained = {"iteration": 0, "wall_time_s": 0.0, "eval_mean_score": -11.0}  # as the driver writes it
    (path / run_dir.METRICS_FILE).write_text("".join(json.dumps(row) + "\n" for row in [untrained, *rows]))


def test_summary_keeps_the_curve_times_and_a_held_out_interval(summarise, tmp_path):
    _run(tmp_path / "a", [-9.5, None, -7.25])
    evaluation = {"episodes": 100, "seed": 0, "mean_score": -5.0, "std_score": 2.0, "greedy_score": -1.0,
                  "env": "collect", "iteration": 3, "ci95": [-5.5, -4.7]}  # as pizero eval wrote it
    (tmp_path / "a.json").write_text(json.dumps(evaluation))
    _run(tmp_path / "b", [-10.0])
    out = tmp_path / "summary.json"
    assert summarise.main(["--out", str(out), "--command", "pizero train ...",
                           f"centred={tmp_path / 'a'}:{tmp_path / 'a.json'}", f"other={tmp_path / 'b'}"]) == 0
    record = json.loads(out.read_text())
    assert record["command"] == "pizero train ..." and record["machine"].startswith("2 CPU cores, 2 workers")
    a, b = record["runs"]["centred"], record["runs"]["other"]
    assert a["iterations"] == 3 and a["training_s"] == 6.0 and a["median_iteration_s"] == 2.5
    assert a["curve_iteration_score_wall_s"] == [[0, -11.0, 0.0], [1, -9.5, 2.0], [3, -7.25, 6.0]]
    assert a["env_args"] == [["view", "centred"]] and a["planner"] == "none"
    assert a["parameter_norm_at_end"] == 23.0
    assert (a["weight_decay"], a["episodes_per_member"], a["fitness_shaping"]) == (0.0, 1, "centered_ranks")
    # the interval is eval's own (not 1.96 standard errors, -5.392 to -4.608, recomputed here)
    assert a["held_out"]["ci95"] == [-5.5, -4.7] and a["held_out"]["references"] == {"greedy_score": -1.0}
    assert "held_out" not in b and b["iterations"] == 1


def test_a_run_without_a_label_is_a_one_line_error(summarise, tmp_path, capsys):
    with pytest.raises(SystemExit):
        summarise.main(["--out", str(tmp_path / "x.json"), "--command", "c", str(tmp_path)])
    assert "must read LABEL=RUN_DIR[:EVAL_JSON], got" in capsys.readouterr().err


def test_summary_says_how_often_the_whole_population_tied(summarise, tmp_path):
    _run(tmp_path / "a", [None] * 20, spreads=[3.0, 2.0] + [0.0] * 17 + [1.0])
    out = tmp_path / "summary.json"
    assert summarise.main(["--out", str(out), "--command", "c", "--machine", "two runs side by side",
                           f"a={tmp_path / 'a'}"]) == 0
    record = json.loads(out.read_text())
    a = record["runs"]["a"]
    assert record["machine"] == "two runs side by side"
    assert a["all_tied_iterations_fraction"] == 0.85
    assert a["best_member_score_first_tenth"] == -6.0 and a["best_member_score_after"] == -8.0
