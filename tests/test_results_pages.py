"""Every published result is written once: docs/results/summary.json is what its source JSONs give
(scripts/build_summary.py), and every generated block of README.md and docs/*.md is what summary.json and
docs/results/planning.json give (scripts/render_results.py). A page that disagrees with its JSON fails here."""

import json
import shutil

import pytest

from tests.scripts_loading import load_script

build_summary = load_script("build_summary")
render_results = load_script("render_results")

EXPECTED_BLOCKS = {
    "README.md": {"results"},
    "docs/learning.md": {"scores", "paired", "hand"},
    "docs/baselines.md": {"baselines"},
    **{f"docs/{page}.md": {"current-best"} for page in ("tsp", "collect", "sokoban", "2048", "flp", "pacman")},
}


def test_summary_json_is_what_its_sources_give():
    assert build_summary.OUT.read_text() == build_summary.text(), \
        "docs/results/summary.json is stale: python scripts/build_summary.py"


def test_every_page_agrees_with_its_json():
    assert render_results.stale() == [], "python scripts/render_results.py rewrites these pages"


def test_each_page_has_its_generated_blocks():
    for page, names in EXPECTED_BLOCKS.items():
        found = set(render_results.BLOCK.findall((render_results.REPO / page).read_text()))
        assert names <= found, f"{page} lacks the generated blocks {sorted(names - found)}"


def test_one_sign_convention_higher_is_better():
    summary = json.loads(build_summary.OUT.read_text())
    tsp = next(env for env in summary["environments"] if env["env"] == "tsp")
    assert all(env["higher_is_better"] for env in summary["environments"])
    assert tsp["target"]["score"] < 0 and all(s["score"] < 0 for a in tsp["agents"] for s in a["seeds"])
    assert tsp["natural_unit"]["name"] == "tour length"


def test_a_target_is_reached_only_by_a_mean_over_three_seeds():
    summary = json.loads(build_summary.OUT.read_text())
    for env in summary["environments"]:
        for agent in env["agents"]:
            if agent["reached"]:
                assert agent["n_seeds"] >= 3 and agent["mean"] >= env["target"]["score"], (env["env"], agent["key"])
        assert env["target"]["reached"] == any(a["reached"] for a in env["agents"])


def test_every_figure_names_its_source():
    summary = json.loads(build_summary.OUT.read_text())
    for env in summary["environments"]:
        for agent in env["agents"]:
            assert agent["command"].startswith("pizero train"), (env["env"], agent["key"])
            for seed in agent["seeds"]:
                source = seed["source"]
                if seed.get("hand"):
                    assert source.startswith("docs only"), (env["env"], agent["key"], seed)
                else:
                    assert source["file"] in summary["sources"], source
                    assert "command" in summary["sources"][source["file"]], source


def test_numbers_are_written_one_way():
    number, interval = render_results.number, render_results.interval
    assert number(-0.0008445033431053162, 4, sign=True) == "-0.0008"
    assert interval([-0.004234596638545597, 0.0026146115600702443], 4, sign=True) == "(-0.0042, +0.0026)"
    assert number(5075, 0) == "5,075" and number(5073.361, 0) == "5,073"
    assert number(-0.0001, 3) == "0.000" and number(-2.9917666, 3) == "-2.992"
    assert render_results.as_written(-2.0) == "-2.0" and render_results.as_written(5000) == "5,000"


def _row(env, seed, ablation, difference, default=True, minutes=10):
    return {"env": env, "seed": seed, "config": "default" if default else "other", "ablation": ablation,
            "paired_difference": difference, "ci95": [difference - 0.1, difference + 0.1], "share_changed": 0.5,
            "share_actions_changed": None, "default": default, "minutes": minutes}


def _readme_row(text: str, env: str) -> str:
    return next(line for line in text.splitlines() if line.startswith(f"| [{env}]("))


@pytest.fixture
def tmp_repo(tmp_path):
    """A copy of the README with its results block emptied, to be generated again."""
    (tmp_path / "docs").mkdir()
    text = (render_results.REPO / "README.md").read_text()
    emptied = render_results.BLOCK.sub(
        lambda m: render_results.BEGIN.format(name=m.group(1)) + "\n" + render_results.END, text)
    (tmp_path / "README.md").write_text(emptied)
    return tmp_path


def test_without_planning_json_the_plan_column_says_not_measured_yet(tmp_repo):
    assert render_results.stale(repo=tmp_repo, planning_path=tmp_repo / "absent.json", write=True) == ["README.md"]
    text = (tmp_repo / "README.md").read_text()
    for env in ("tsp", "collect", "2048", "pacman-po"):
        assert _readme_row(text, env).endswith("| not measured yet |")


def test_the_plan_column_is_the_default_configs_mean_over_seeds_at_its_longest_budget(tmp_repo):
    planning = tmp_repo / "planning.json"
    rows = [_row("tsp", 0, "shuffled", -0.10), _row("tsp", 1, "shuffled", -0.14), _row("tsp", 2, "shuffled", -0.12),
            _row("tsp", 0, "simulations=1", -0.40), _row("tsp", 1, "simulations=1", -0.38),
            _row("tsp", 2, "simulations=1", -0.42), _row("tsp", 0, "zeroed", -0.9),
            _row("tsp", 0, "simulations=30", 0.01), _row("tsp", 3, "shuffled", -5.0, default=False),
            _row("2048", 0, "shuffled", -250.4, minutes=30), _row("2048", 0, "shuffled", -9.0, minutes=10)]
    planning.write_text(json.dumps({"ablations": rows, "verdicts": [], "runs": {}}))
    render_results.stale(repo=tmp_repo, planning_path=planning, write=True)
    text = (tmp_repo / "README.md").read_text()
    assert _readme_row(text, "tsp").endswith("| shuffled -0.120, 1 simulation -0.400 (3 seeds, 10 minutes) |")
    assert _readme_row(text, "2048").endswith("| shuffled -250 (1 seed, 30 minutes) |")
    assert _readme_row(text, "collect").endswith("| not measured yet |")
    assert render_results.stale(repo=tmp_repo, planning_path=planning) == []
    assert render_results.stale(repo=tmp_repo, planning_path=tmp_repo / "absent.json") == ["README.md"]


def test_a_hand_edited_figure_is_caught(tmp_repo):
    render_results.stale(repo=tmp_repo, planning_path=tmp_repo / "absent.json", write=True)
    text = (tmp_repo / "README.md").read_text()
    assert "-2.972, 3 seeds" in text  # TSP's planner-free mean, a figure the table shows
    (tmp_repo / "README.md").write_text(text.replace("-2.972, 3 seeds", "-2.97, 3 seeds", 1))
    assert render_results.stale(repo=tmp_repo, planning_path=tmp_repo / "absent.json") == ["README.md"]


def test_an_unknown_block_is_refused(tmp_repo):
    page = tmp_repo / "docs" / "x.md"
    page.write_text(render_results.BEGIN.format(name="nonsense") + "\n" + render_results.END + "\n")
    with pytest.raises(ValueError, match="unknown generated block 'nonsense'"):
        render_results.stale(repo=tmp_repo, planning_path=tmp_repo / "absent.json")


def test_planning_json_outside_git_counts_when_present(tmp_path):
    path = tmp_path / "planning.json"
    assert not render_results.committed(path)
    shutil.copy(build_summary.OUT, path)
    assert render_results.committed(path)
