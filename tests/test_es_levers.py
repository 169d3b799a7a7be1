"""scripts/es_levers.py: an ES setting against the default, paired on the same episodes, rows of one JSON."""

import json

import pytest

from pizero_ray.config import build_config
from pizero_ray.storage import run_dir
from tests.scripts_loading import load_script

es_levers = load_script("es_levers")
paired_results = load_script("paired_results")


def _run(path, **settings):
    run_dir.write_config(path, build_config("tiny", planner="none", seed=3, **settings))
    return path


def test_a_setting_is_paired_with_the_default_run_of_its_seed_once(tmp_path, monkeypatch):
    common = _run(tmp_path / "common" / "run", common_episodes=True)
    default = _run(tmp_path / "default" / "run")
    out = tmp_path / "levers.json"
    data = es_levers.compare(out, [(common, default)], "common-episodes", 8, 0, progress=lambda text: None)
    assert json.loads(out.read_text()) == data
    (row,) = data["comparisons"]
    assert (row["env"], row["seed"], row["method"], row["setting"], row["minutes"]) == (
        "tsp", 3, "pizero", "common-episodes", 0)
    assert row["paired_difference"] == pytest.approx(row["setting_score"] - row["default_score"])
    assert data["runs"][row["setting_run"]]["common_episodes"] is True
    assert data["runs"][row["default_run"]]["setting"] == "default"

    def measured_again(*args, **kwargs):
        raise AssertionError("a pair already in the file was measured again")

    monkeypatch.setattr(es_levers, "compare_runs", measured_again)
    assert es_levers.compare(out, [(common, default)], "common-episodes", 8, 0,
                             progress=lambda text: None)["comparisons"] == data["comparisons"]
    again = _run(tmp_path / "again" / "run", common_episodes=True)  # the same seed and setting, another run
    with pytest.raises(ValueError, match="would repeat the row .* measured on "):
        es_levers.compare(out, [(again, default)], "common-episodes", 8, 0, progress=lambda text: None)


def test_runs_of_another_seed_or_of_one_batch_are_refused(tmp_path):
    other = tmp_path / "other"
    run_dir.write_config(other, build_config("tiny", planner="none", seed=4))
    with pytest.raises(ValueError, match="is not a run of"):
        es_levers.compare(tmp_path / "p.json", [(_run(tmp_path / "a"), other)], "x", 8, 0)
    with pytest.raises(ValueError, match="would both be named"):
        es_levers.compare(tmp_path / "p.json", [(_run(tmp_path / "a"), _run(tmp_path / "b"))], "x", 8, 0)
    assert not (tmp_path / "p.json").exists()


def test_each_setting_ends_with_its_mean_and_how_many_seeds_are_clear_of_zero():
    def row(seed, setting, difference):
        return {"env": "tsp", "seed": seed, "method": "es", "setting": setting, "minutes": 10,
                "paired_difference": difference, "ci95": [difference - 0.01, difference + 0.01],
                "setting_score": -2.9 + difference, "default_score": -2.9, "setting_iterations": 4000,
                "default_iterations": 4500}

    data = {"comparisons": [row(1, "common", 0.02), row(0, "common", 0.005), row(0, "ranks", -0.03)]}
    lines = es_levers.comparison_table(data, {"tsp": 3})[2:]
    assert [line.split(" | ")[2:5] for line in lines] == [
        ["common", "10", "0"], ["common", "10", "1"], ["common", "10", "mean of 2"],
        ["ranks", "10", "0"], ["ranks", "10", "mean of 1"]]
    assert lines[0].endswith("| -2.895 | -2.900 | +0.005 (-0.005, +0.015) | 4,000, 4,500 |")
    assert "**+0.013**: 1 above zero, 0 below" in lines[2]
    begin = es_levers.BEGIN.format(name="tsp")
    page = es_levers.render_page(f"{begin}\n{paired_results.END}\n",
                                 data | {"comparisons": data["comparisons"] + [dict(row(0, "x", 1.0), env="flp")]},
                                 {"tsp": 3, "flp": 4})
    assert "| tsp | es | common | 10 | mean of 2 |" in page and "flp" not in page
    assert es_levers.summary_lines(data, {"tsp": 3})[1] == (
        "- **tsp**, es, `ranks` for 10 minutes, minus the default: -0.030 (of 1 seed: 1 below zero, 0 above).")


def test_every_page_with_lever_tables_is_what_its_json_gives():
    """docs/learning.md's lever tables, and each environment page's block, are generated from
    docs/results/es_levers.json: a hand edit fails here."""
    from pathlib import Path

    root = Path(__file__).resolve().parents[1]
    data = es_levers.load(root / "docs" / "results" / "es_levers.json", ("comparisons",))
    marker = es_levers.BEGIN.split("{")[0]
    pages = [path for path in sorted((root / "docs").glob("*.md")) if marker in path.read_text()]
    assert root / "docs" / "learning.md" in pages and len(pages) >= 3
    for path in pages:
        page = path.read_text()
        assert es_levers.render_page(page, data) == page, path.name
