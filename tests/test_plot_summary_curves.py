"""scripts/plot_summary_curves.py: curves from committed summaries, whose run dirs are gone."""

import json

import pytest

from tests.figures import assert_curves_drawn
from tests.scripts_loading import load_script


@pytest.fixture(scope="module")
def script():
    return load_script("plot_summary_curves")


@pytest.fixture
def summary(tmp_path):
    path = tmp_path / "summary.json"
    runs = {"none": {"env": "tsp", "curve_iteration_score_wall_s": [[0, -3.9, 0.0], [100, -3.0, 300.0]]},
            "pizero": {"env": "tsp", "curve_iteration_score_wall_s": [[0, -3.6, 0.0], [20, -3.1, 300.0]]}}
    path.write_text(json.dumps({"command": "c", "runs": runs}))
    return path


def test_summary_curve_reads_the_rows_a_run_dir_would_give(script, summary):
    env, rows = script.summary_curve(summary, "none")
    assert env == "tsp"
    assert rows == [{"iteration": 0, "eval_mean_score": -3.9, "wall_time_s": 0.0},
                    {"iteration": 100, "eval_mean_score": -3.0, "wall_time_s": 300.0}]


def test_main_draws_one_png_from_two_runs(script, summary, tmp_path):
    out = tmp_path / "figure" / "curves.png"
    assert script.main(["--out", str(out), "--title", "t", f"a={summary}:none", f"b={summary}:pizero"]) == 0
    # 11 x 4 inches at 110 dpi; both panels (score against iteration, against minutes) draw both runs' lines
    assert_curves_drawn(out, size=(1210, 440), panels=[("C0", "C1")] * 2)


def test_a_missing_run_is_named(script, summary, tmp_path):
    with pytest.raises(SystemExit, match="no run 'gone'"):
        script.main(["--out", str(tmp_path / "x.png"), "--title", "t", f"a={summary}:gone"])
