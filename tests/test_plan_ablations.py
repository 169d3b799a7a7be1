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
