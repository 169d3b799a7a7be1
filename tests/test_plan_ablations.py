"""scripts/plan_ablations.py: each run's ablations as rows of one JSON, resumable, from the package's own
evaluation (eval --plan, compare --simulations-a)."""

import json
from pathlib import Path

import pytest

from pizero_ray.config import build_config
from pizero_ray.storage import run_dir
from tests.scripts_loading import load_script

plan_ablations = load_script("plan_ablations")
paired_results = load_script("paired_results")


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
    assert shuffled["minutes"] == 0  # an untrained run
    assert shuffled["paired_difference"] == 0.0 and shuffled["ci95"] == [0.0, 0.0]
    assert shuffled["share_changed"] == 0.0 and shuffled["share_actions_changed"] == 0.0
    assert rows["simulations=1"]["share_actions_changed"] is None
    (record,) = data["runs"].values()
    assert (record["iterations"], record["config"], record["last_plan_shuffled_difference"]) == (0, "blind", None)

    def measured_again(*args):
        raise AssertionError("a row already in the file was measured again")

    monkeypatch.setattr(plan_ablations, "measure", measured_again)
    assert plan_ablations.update(out, [blind_run], "blind", False, ["shuffled"], 8, 0,
                                 progress=lambda text: None)["ablations"] == data["ablations"]


def test_a_second_run_of_a_measured_seed_and_configuration_is_refused_not_merged(blind_run, tmp_path):
    out = tmp_path / "planning.json"
    data = plan_ablations.update(out, [blind_run], "blind", False, ["shuffled"], 8, 0, progress=lambda text: None)
    again = tmp_path / "again" / "run"  # the same environment, seed, configuration and minutes, another run
    run_dir.write_config(again, build_config("tiny", decoder_inputs=("state",), seed=4))
    with pytest.raises(ValueError, match="would repeat the row .* measured on "):
        plan_ablations.update(out, [again], "blind", False, ["shuffled"], 8, 0, progress=lambda text: None)
    (row,) = plan_ablations._load(out)["ablations"]
    assert row == data["ablations"][0]  # still the first run's


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
    assert {data["runs"][row["pizero_run"]]["config"], data["runs"][row["planner_free_run"]]["config"]} == {
        "blind", "planner-free"}
    assert row["paired_difference"] == pytest.approx(row["pizero_score"] - row["planner_free_score"])
    other_seed = tmp_path / "none-seed5"
    run_dir.write_config(other_seed, build_config("tiny", planner="none", seed=5))
    with pytest.raises(ValueError, match="is not the planner-free run"):
        plan_ablations.judge(tmp_path / "p.json", [(blind_run, other_seed)], "x", False, "equal_time", 8, 0)


def test_a_run_trained_to_the_iterations_of_a_timed_run_stands_under_its_budget(blind_run, tmp_path):
    out = tmp_path / "p.json"
    plan_ablations.update(out, [blind_run], "blind", False, ["shuffled"], 8, 0, progress=lambda text: None)
    planner_free = tmp_path / "none"
    run_dir.write_config(planner_free, build_config("tiny", planner="none", seed=4))
    rebuilt = tmp_path / "rebuilt" / "runs" / "tsp" / "blind" / "seed4"  # trained to the same count, elsewhere
    run_dir.write_config(rebuilt, build_config("tiny", decoder_inputs=("state",), seed=4))
    with pytest.raises(ValueError, match="has the iterations of no 3-minute blind run of tsp seed 4: it made 0"):
        plan_ablations.judge(out, [(rebuilt, planner_free)], "blind", False, "equal_iterations", 8, 0, minutes=3)
    with pytest.raises(ValueError, match="equal iterations only, not equal_time"):
        plan_ablations.judge(out, [(rebuilt, planner_free)], "blind", False, "equal_time", 8, 0, minutes=0)
    assert plan_ablations._load(out)["verdicts"] == []
    data = plan_ablations.judge(out, [(rebuilt, planner_free)], "blind", False, "equal_iterations", 8, 0,
                                progress=lambda text: None, minutes=0)
    (row,) = data["verdicts"]
    (ablation,) = data["ablations"]
    assert row["iterations_of"] == ablation["run"] != row["pizero_run"] == "rebuilt/tsp/blind/seed4"
    assert row["minutes"] == 0 and data["runs"][row["pizero_run"]]["config"] == "blind"


def test_a_choice_pairs_two_pizero_configurations_of_one_seed_and_budget(blind_run, tmp_path, monkeypatch, capsys):
    reader = tmp_path / "batch" / "runs" / "tsp" / "reader" / "seed4"
    run_dir.write_config(reader, build_config("tiny", decoder_inputs=("action", "visits"), seed=4))
    out = tmp_path / "p.json"
    data = plan_ablations.choose(out, [(reader, blind_run)], "reads-the-plan", "blind", 8, 0,
                                 progress=lambda text: None)
    (row,) = data["choices"]
    assert (row["env"], row["seed"], row["config"], row["against"], row["minutes"]) == (
        "tsp", 4, "reads-the-plan", "blind", 0)
    assert row["paired_difference"] == pytest.approx(row["config_score"] - row["against_score"])
    assert data["runs"][row["config_run"]]["config"] == "reads-the-plan"
    assert data["runs"][row["against_run"]]["config"] == "blind"

    def compared_again(*args, **kwargs):
        raise AssertionError("a choice already in the file was measured again")

    monkeypatch.setattr(plan_ablations, "compare_runs", compared_again)
    assert plan_ablations.choose(out, [(reader, blind_run)], "reads-the-plan", "blind", 8, 0,
                                 progress=lambda text: None)["choices"] == data["choices"]
    planner_free = tmp_path / "none"
    run_dir.write_config(planner_free, build_config("tiny", planner="none", seed=4))
    other_seed = tmp_path / "seed5"
    run_dir.write_config(other_seed, build_config("tiny", seed=5))
    for incumbent in (planner_free, other_seed):
        with pytest.raises(ValueError, match="is not a PiZero run of .* environment and seed"):
            plan_ablations.choose(out, [(reader, incumbent)], "x", "y", 8, 0)
    with pytest.raises(SystemExit):  # on the command line: one line, no traceback
        plan_ablations.main(["choose", "--out", str(out), "--config", "x", "--against", "y",
                             f"{reader}={planner_free}"])
    err = capsys.readouterr().err
    (line,) = [line for line in err.splitlines() if "error:" in line]
    assert "is not a PiZero run of" in line and "Traceback" not in err


def test_each_choice_ends_with_its_mean_and_how_many_seeds_are_clear_of_zero():
    def choice(seed, difference):
        return {"env": "collect", "seed": seed, "config": "gumbel", "against": "puct", "minutes": 10,
                "config_score": -2.0 + difference, "against_score": -2.0, "paired_difference": difference,
                "ci95": [difference - 0.1, difference + 0.1], "config_iterations": 3000, "against_iterations": 500}

    lines = plan_ablations.choice_table({"choices": [choice(1, 0.05), choice(0, 1.0)]}, {"collect": 2})[2:]
    assert lines[0] == "| collect | gumbel | puct | 10 | 0 | -1.00 | -2.00 | +1.00 (+0.90, +1.10) | 3,000, 500 |"
    assert lines[1].split(" | ")[4] == "1"
    assert lines[2] == "| collect | gumbel | puct | 10 | mean of 2 | | | **+0.53**: 1 above zero, 0 below | |"


def test_the_page_is_regenerated_between_its_markers_only():
    data = {"ablations": [
        {"env": "tsp", "seed": s, "config": "default", "minutes": 10, "ablation": a, "paired_difference": d,
         "ci95": [d - 1, d + 0.75],
         "default": True, "intact_mean_score": -3.0, "share_actions_changed": 0.25 if a == "shuffled" else None}
        for s, d in ((0, -0.5), (1, -1.5)) for a in ("simulations=1", "shuffled")],
        "verdicts": [], "runs": {}}
    begin = plan_ablations.BEGIN.format(name="ablations")
    page = f"# Planning\n\nbefore\n{begin}\nold table\n{paired_results.END}\nafter\n"
    rendered = plan_ablations.render_page(page, data, {"tsp": 2})
    assert rendered.startswith("# Planning\n\nbefore\n") and rendered.endswith(f"{paired_results.END}\nafter\n")
    header, _, seed0, seed1, mean = rendered.split(begin)[1].strip().splitlines()[:5]
    assert header == ("| environment | configuration | minutes | seed | intact score | shuffled | simulations=1 | "
                      "actions the shuffled plan changes |")
    assert seed0 == "| tsp | default | 10 | 0 | -3.00 | -0.50 (-1.50, +0.25) | -0.50 (-1.50, +0.25) | 25.0% |"
    assert mean == ("| tsp | default | 10 | mean of 2 | | **-1.00**, 1 of 2 below zero | "
                    "**-1.00**, 1 of 2 below zero | |")
    assert seed1.startswith("| tsp | default | 10 | 1 |")
    assert plan_ablations.render_page(rendered, data, {"tsp": 2}) == rendered


def test_runs_of_two_batches_keep_their_own_names(tmp_path):
    record = {"env": "collect", "method": "pizero", "seed": 1}
    in_experiment = tmp_path / "screen" / "runs" / "collect" / "pizero" / "seed1"
    assert plan_ablations.run_key(in_experiment, record) == "screen/collect/pizero/seed1"
    assert plan_ablations.run_key(tmp_path / "verdicts" / "run", record) == "verdicts/collect/pizero/seed1"


def test_two_configurations_of_one_seed_in_one_batch_keep_their_own_names(tmp_path):
    record = {"env": "collect", "method": "pizero", "seed": 0}
    batch = tmp_path / "screens" / "runs" / "collect"
    names = {plan_ablations.run_key(batch / folder / "seed0", record) for folder in ("gumbel", "readplan")}
    assert names == {"screens/collect/gumbel/seed0", "screens/collect/readplan/seed0"}


def test_a_second_run_under_a_taken_name_is_refused():
    runs = {}
    first = {"env": "collect", "seed": 0, "planner": "gumbel", "iterations": 10, "config": "gumbel"}
    paired_results.remember_run(runs, "b/collect/pizero/seed0", Path("a"), first)
    paired_results.remember_run(runs, "b/collect/pizero/seed0", Path("a"), dict(first))  # the same run again
    with pytest.raises(ValueError, match="b/collect/pizero/seed0"):
        paired_results.remember_run(runs, "b/collect/pizero/seed0", Path("c"), dict(first, planner="muzero"))
    assert runs == {"b/collect/pizero/seed0": first}


def test_the_planning_page_is_what_its_json_gives():
    """docs/planning.md's tables are generated from docs/results/planning.json: a hand edit fails here."""

    root = Path(__file__).resolve().parents[1]
    page = (root / "docs" / "planning.md").read_text()
    data = plan_ablations._load(root / "docs" / "results" / "planning.json")
    assert plan_ablations.render_page(page, data) == page


def test_each_budgets_verdicts_end_with_their_mean_and_how_many_seeds_are_clear_of_zero():
    def verdict(seed, budget, difference, minutes=10):
        return {"env": "collect", "seed": seed, "config": "default", "minutes": minutes, "budget": budget,
                "pizero_score": -4.0,
                "planner_free_score": -4.0 - difference, "paired_difference": difference,
                "ci95": [difference - 0.1, difference + 0.1], "pizero_iterations": 500,
                "planner_free_iterations": 3000, "pizero_plan_shuffled_difference": -0.5, "default": True}

    data = {"verdicts": [verdict(1, "equal_time", -2.0), verdict(0, "equal_iterations", 0.05),
                         verdict(0, "equal_time", -1.0), verdict(0, "equal_time", 0.5, minutes=30)]}
    lines = plan_ablations.verdict_table(data, {"collect": 2})[2:]
    assert [line.split(" | ")[2:5] for line in lines] == [
        ["10", "equal time", "0"], ["10", "equal time", "1"], ["10", "equal time", "mean of 2"],
        ["10", "equal iterations", "0"], ["10", "equal iterations", "mean of 1"],
        ["30", "equal time", "0"], ["30", "equal time", "mean of 1"]]
    assert "**-1.50**: 0 above zero, 2 below" in lines[2] and "**+0.05**: 0 above zero, 0 below" in lines[4]
    assert lines[0].endswith("| -1.00 (-1.10, -0.90) | 500, 3,000 | -0.50 |")


def test_the_summary_gives_each_environments_default_and_counts_seeds_clear_of_zero():
    def ablation(seed, name, difference, default=True, minutes=10):
        return {"env": "collect", "seed": seed, "config": "default" if default else "other", "minutes": minutes,
                "ablation": name, "paired_difference": difference, "ci95": [difference - 0.2, difference + 0.2],
                "default": default}

    data = {"ablations": [ablation(0, "shuffled", -1.0), ablation(1, "shuffled", -0.1),
                          ablation(0, "simulations=1", 0.5), ablation(0, "shuffled", -9.0, default=False),
                          ablation(0, "shuffled", -3.0, minutes=30),
                          dict(ablation(0, "shuffled", -2.0), env="tsp", config="reads-the-plan")],
            "verdicts": [{"env": "collect", "seed": 0, "config": "default", "minutes": 10, "budget": "equal_time",
                          "paired_difference": -2.0, "ci95": [-2.1, -1.9], "default": True}]}
    assert plan_ablations.summary_lines(data, {"collect": 1}) == [
        "- **collect** at the default, 10 minutes: plan shuffled -0.6 (of 2 seeds: 1 below zero, 0 above); "
        "1 simulation +0.5 (of 1 seed: 0 below zero, 1 above); PiZero minus the planner-free agent at equal time "
        "-2.0 (of 1 seed: 1 below zero, 0 above).",
        "- **collect** at the default, 30 minutes: plan shuffled -3.0 (of 1 seed: 1 below zero, 0 above).",
        "- **collect** `other`, 10 minutes: plan shuffled -9.0 (of 1 seed: 1 below zero, 0 above).",
        "- **tsp** `reads-the-plan`, the default, 10 minutes: plan shuffled -2.000 (of 1 seed: 1 below zero, 0 above)."]
