"""scripts/plan_ablations.py: each run's ablations as rows of one JSON, resumable, from the package's own
evaluation (eval --plan, compare --simulations-a)."""

import json

import pytest

from pizero_ray.config import build_config
from pizero_ray.storage import run_dir
from tests.scripts_loading import load_script

plan_ablations = load_script("plan_ablations")


@pytest.fixture(scope="module")
def blind_run(tmp_path_factory):
    """An untrained tiny PiZero whose decoder cannot read its plan."""
    path = tmp_path_factory.mktemp("blind") / "run"
    run_dir.write_config(path, build_config("tiny", decoder_inputs=("state",), seed=4))
    return path


def test_rows_say_what_each_ablation_costs_and_a_second_pass_measures_nothing(blind_run, tmp_path, monkeypatch):
    out = tmp_path / "planning.json"
    data = plan_ablations.update(out, [blind_run], "blind", False, ["shuffled", "simulations=1"], 8, 0,
                                 progress=lambda text: None)
    assert json.loads(out.read_text()) == data
    rows = {row["ablation"]: row for row in data["ablations"]}
    assert set(rows) == {"shuffled", "simulations=1"}
    shuffled = rows["shuffled"]
    assert (shuffled["env"], shuffled["seed"], shuffled["config"], shuffled["default"]) == ("tsp", 4, "blind", False)
    assert shuffled["paired_difference"] == 0.0 and shuffled["ci95"] == [0.0, 0.0]
    assert shuffled["share_changed"] == 0.0 and shuffled["share_actions_changed"] == 0.0
    assert rows["simulations=1"]["share_actions_changed"] is None
    assert data["runs"]["tsp/blind/seed4"]["iterations"] == 0

    def measured_again(*args):
        raise AssertionError("a row already in the file was measured again")

    monkeypatch.setattr(plan_ablations, "measure", measured_again)
    assert plan_ablations.update(out, [blind_run], "blind", False, ["shuffled"], 8, 0,
                                 progress=lambda text: None)["ablations"] == data["ablations"]


def test_an_unknown_ablation_is_refused_before_any_measurement(blind_run, tmp_path):
    with pytest.raises(ValueError, match="unknown ablation 'simulations=0'"):
        plan_ablations.update(tmp_path / "p.json", [blind_run], "blind", False, ["simulations=0"], 8, 0)
    assert not (tmp_path / "p.json").exists()


def test_verdicts_pair_pizero_with_the_planner_free_run_of_its_seed(blind_run, tmp_path):
    planner_free = tmp_path / "none"
    run_dir.write_config(planner_free, build_config("tiny", planner="none", seed=4))
    data = plan_ablations.judge(tmp_path / "p.json", [(blind_run, planner_free)], "blind", False, "equal_time", 8, 0,
                                progress=lambda text: None)
    (row,) = data["verdicts"]
    assert (row["env"], row["seed"], row["budget"]) == ("tsp", 4, "equal_time")
    assert row["paired_difference"] == pytest.approx(row["pizero_score"] - row["planner_free_score"])
    other_seed = tmp_path / "none-seed5"
    run_dir.write_config(other_seed, build_config("tiny", planner="none", seed=5))
    with pytest.raises(ValueError, match="is not the planner-free run"):
        plan_ablations.judge(tmp_path / "p.json", [(blind_run, other_seed)], "x", False, "equal_time", 8, 0)


def test_the_page_is_regenerated_between_its_markers_only():
    data = {"ablations": [
        {"env": "tsp", "seed": s, "config": "default", "ablation": a, "paired_difference": d, "ci95": [d - 1, d + 1],
         "default": True} for s, d in ((0, -0.5), (1, -1.5)) for a in ("simulations=1", "shuffled")],
        "verdicts": [], "runs": {}}
    begin = plan_ablations.BEGIN.format(name="ablations")
    page = f"# Planning\n\nbefore\n{begin}\nold table\n{plan_ablations.END}\nafter\n"
    rendered = plan_ablations.render_page(page, data)
    assert rendered.startswith("# Planning\n\nbefore\n") and rendered.endswith(f"{plan_ablations.END}\nafter\n")
    header, _, row = rendered.split(begin)[1].strip().splitlines()[:3]
    assert header == "| environment | configuration | seeds | shuffled | simulations=1 |"
    assert row.startswith("| tsp | default (default) | 2 | **-1.000** (seed 0: -0.500 (-1.500, +0.500); seed 1:")
    assert plan_ablations.render_page(rendered, data) == rendered
