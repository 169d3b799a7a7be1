"""`pizero compare` and `pizero eval --per-episode`: two agents on the same episodes, and each episode's score.

The trained run is trained here, in this process, by the trainer's own ES steps (ask, score every pair, tell)
on the cheapest agent to compile; the untrained run holds a config and no checkpoint (its initial parameters).
"""

import json

import numpy as np
import pytest

from pizero_ray import methods
from pizero_ray.cli import main
from pizero_ray.cli.compare import text_report
from pizero_ray.config import ConfigError, build_config
from pizero_ray.es import population
from pizero_ray.evaluation.runs import check_same_episodes, compare_runs, environment, evaluate_run
from pizero_ray.storage import checkpoints, run_dir, runs

CONFIG = build_config("tiny", env="tsp", planner="none", population=16, chunk_size=16)
ITERATIONS = 20  # on TSP10, 64 episodes' mean tour goes from about 5.1 (untrained) to about 3.4


def _train_here(path, config, iterations):
    """ES as the trainer steps it, the population in one chunk, then the run's checkpoint as the driver saves it."""
    env = methods.make_env(config)
    state, layout, strategy = methods.initial_state(config, env)
    scorer = population.make_pair_scorer(config, env, layout)
    pairs, everyone = np.arange(config.population, dtype=np.int32), np.ones(config.population, bool)
    for _ in range(iterations):
        seed = np.uint32(strategy.ask(state))
        noise = strategy.parts.noise(seed, np.int32(0))
        scores = np.asarray(scorer(state.theta, seed, pairs, noise))
        state, _ = strategy.tell(state, scores, everyone,
                                 [strategy.parts.from_noise(strategy.weights(scores, everyone), noise)])
    run_dir.write_config(path, config)
    writer = checkpoints.CheckpointWriter(path)
    runs.save(writer, config, state)
    writer.close()


@pytest.fixture(scope="module")
def runs_here(tmp_path_factory):
    """name -> run dir: 'trained' (ITERATIONS ES steps) and 'untrained' (the same config, no checkpoint)."""
    root = tmp_path_factory.mktemp("compare")
    paths = {name: root / name for name in ("trained", "untrained")}
    _train_here(paths["trained"], CONFIG, ITERATIONS)
    run_dir.write_config(paths["untrained"], CONFIG)
    return paths


def _run(argv, capsys):
    try:
        code = main(argv)
    except SystemExit as exit_:  # argparse's own errors
        code = exit_.code
    captured = capsys.readouterr()
    return code, captured.out, captured.err.strip().splitlines()


def _compare(a, b, capsys, *extra):
    code, out, err = _run(["compare", str(a), str(b), "--json", *extra], capsys)
    assert code == 0, err
    return json.loads(out)


@pytest.fixture(scope="module")
def same_agent_twice(runs_here):
    """What `pizero compare` finds for the trained run against itself, on 64 episodes."""
    return compare_runs(runs_here["trained"], runs_here["trained"], episodes=64, seed=0)


def test_the_same_agent_twice_differs_by_exactly_zero_on_every_episode(same_agent_twice):
    result = same_agent_twice
    assert result["iteration_a"] == result["iteration_b"] == ITERATIONS
    # Both play seed 0's episodes: on any other episodes the same agent would score otherwise somewhere.
    assert result["mean_difference"] == 0.0 and result["ci95"] == [0.0, 0.0]
    assert (result["share_a_higher"], result["share_tied"], result["share_b_higher"]) == (0.0, 1.0, 0.0)


def test_trained_against_untrained_on_evals_episodes(runs_here, capsys):
    trained, untrained = runs_here["trained"], runs_here["untrained"]
    result = _compare(trained, untrained, capsys, "--episodes", "64", "--seed", "2")
    assert (result["iteration_a"], result["iteration_b"]) == (ITERATIONS, 0)
    # Each agent played eval's episodes for the seed: its mean is eval's ...
    assert result["mean_score_a"] == evaluate_run(trained, episodes=64, seed=2)["mean_score"]
    assert result["mean_score_b"] == evaluate_run(untrained, episodes=64, seed=2)["mean_score"]
    assert result["mean_difference"] == pytest.approx(result["mean_score_a"] - result["mean_score_b"], abs=1e-12)
    # ... and the trained agent's tours are shorter by an interval that excludes 0.
    low, high = result["ci95"]
    assert 0.0 < low <= result["mean_difference"] <= high
    assert result["share_a_higher"] > 0.8
    assert result["share_a_higher"] + result["share_tied"] + result["share_b_higher"] == pytest.approx(1.0)


def test_the_text_report_names_both_runs_and_the_shares(runs_here, same_agent_twice):
    lines = text_report(same_agent_twice).splitlines()
    assert lines[0] == f"run A: {runs_here['trained']} (pizero, no planner, tsp, iteration {ITERATIONS})"
    assert lines[2] == "episodes: 64 (seed 0), the same for both"
    assert "mean A - B: +0.0000, 95% BCa interval [+0.0000, +0.0000]" in lines
    assert lines[3].startswith("mean score A: -") and len(lines[3].split(".")[-1]) == 4  # 4 decimals, any size
    assert lines[-1] == "A higher on 0.0% of episodes, tied on 100.0%, B higher on 0.0%"


def test_an_observation_only_difference_plays_the_same_episodes(runs_here, tmp_path, capsys):
    """TSP's paper features change what the agent sees, not the instances: the runs compare."""
    other = tmp_path / "paper-features"
    run_dir.write_config(other, build_config("tiny", env="tsp", planner="none", env_args={"features": "paper"}))
    result = _compare(runs_here["untrained"], other, capsys, "--episodes", "8")
    assert result["env_b"] == "tsp features=paper" and result["share_tied"] < 1.0


def test_a_baseline_on_discretised_actions_plays_pizeros_episodes(tmp_path):
    """AlphaZero sees FLP's continuous actions as a grid (envs.discretised) and the flat view, PiZero the grid
    view: the same instances, so the runs compare."""
    paths = {"pizero": tmp_path / "pizero", "alphazero": tmp_path / "alphazero"}
    run_dir.write_config(paths["pizero"], build_config("tiny", env="flp", env_args={"view": "grid"}))
    run_dir.write_config(paths["alphazero"], build_config("tiny", env="flp", method="alphazero"))
    pizero, alphazero = methods.load_run(paths["pizero"]), methods.load_run(paths["alphazero"])
    assert alphazero.env.spec.discrete and not pizero.env.spec.discrete
    assert (environment(pizero.config), environment(alphazero.config)) == ("flp view=grid", "flp view=flat")
    check_same_episodes(pizero, alphazero, (paths["pizero"], paths["alphazero"]), 16, 0)  # no error
    longer = alphazero._replace(env=alphazero.env._replace(spec=alphazero.env.spec._replace(horizon=4)))
    with pytest.raises(ConfigError, match="play different episodes"):  # the check can tell: another horizon
        check_same_episodes(pizero, longer, (paths["pizero"], paths["alphazero"]), 16, 0)


def test_a_baseline_is_reported_with_the_planner_it_searches_with(runs_here, tmp_path, capsys):
    """AlphaZero's search is config.planner's policy (baselines.search): the report names it as eval does."""
    baseline = tmp_path / "alphazero-gumbel"
    run_dir.write_config(baseline, build_config("tiny", env="tsp", method="alphazero", planner="gumbel"))
    result = _compare(baseline, runs_here["untrained"], capsys, "--episodes", "4")
    assert (result["method_a"], result["planner_a"]) == ("alphazero", "gumbel")
    assert evaluate_run(baseline, episodes=4, seed=0)["planner"] == "gumbel"
    assert text_report(result).splitlines()[0] == (f"run A: {baseline} (alphazero, Gumbel search with 32 simulations, "
                                                   "tsp, iteration 0)")


@pytest.mark.parametrize("env, env_args, named", [("tsp", {"num_cities": 5}, "(tsp num_cities=5)"),
                                                  ("flp", {}, "(flp)")])
def test_runs_on_different_episodes_are_a_one_line_error_naming_both(runs_here, tmp_path, capsys, env, env_args,
                                                                     named):
    other = tmp_path / "other"
    run_dir.write_config(other, build_config("tiny", env=env, planner="none", env_args=env_args))
    code, out, err = _run(["compare", str(runs_here["untrained"]), str(other)], capsys)
    assert code == 2 and len(err) == 1 and out == ""
    assert f"{runs_here['untrained']} (tsp)" in err[0] and f"{other} {named}" in err[0], err


def test_per_episode_scores_are_evals_in_both_formats(runs_here, tmp_path, capsys):
    scores = {}
    for suffix in (".jsonl", ".npy"):
        path = tmp_path / f"scores{suffix}"
        code, out, err = _run(["eval", str(runs_here["trained"]), "--episodes", "16", "--seed", "5", "--json",
                               "--per-episode", str(path)], capsys)
        assert code == 0, err
        report = json.loads(out)
        assert report["per_episode"] == str(path)
        if suffix == ".npy":
            scores[suffix] = np.load(path)
            assert scores[suffix].dtype == np.float64
        else:
            rows = [json.loads(line) for line in path.read_text().splitlines()]
            assert [(row["episode"], row["seed"]) for row in rows] == [(i, 5) for i in range(16)]
            scores[suffix] = np.array([row["score"] for row in rows])
        assert scores[suffix].shape == (16,) and np.mean(scores[suffix]) == report["mean_score"]
    np.testing.assert_array_equal(scores[".jsonl"], scores[".npy"])
    assert len(np.unique(scores[".npy"])) > 1  # one score per episode, not the mean repeated


@pytest.mark.parametrize("argv, named", [
    (["eval", "RUN", "--per-episode", "scores.csv"], "--per-episode must end in .jsonl or .npy, got scores.csv"),
    (["eval", "RUN", "--per-episode", "scores"], "got scores"),
    (["compare", "RUN", "RUN", "--episodes", "1"], "expected a >= 2 integer, got '1'"),
])
def test_bad_input_is_one_line_naming_the_value(runs_here, tmp_path, monkeypatch, capsys, argv, named):
    monkeypatch.chdir(tmp_path)
    code, _, err = _run([str(runs_here["untrained"]) if arg == "RUN" else arg for arg in argv], capsys)
    assert code == 2 and err[-1].startswith(("pizero: error: ", "pizero compare: error: ")), err
    assert named in err[-1], err
    assert list(tmp_path.iterdir()) == []  # nothing written


@pytest.fixture(scope="module")
def planners_here(tmp_path_factory):
    """Untrained tiny PiZero runs with a planner: one whose decoder reads only the abstract state, one whose
    decoder reads only the search's abstract action."""
    root = tmp_path_factory.mktemp("planners")
    paths = {inputs: root / inputs for inputs in ("state", "action")}
    for inputs, path in paths.items():
        run_dir.write_config(path, build_config("tiny", decoder_inputs=(inputs,)))
    return paths


def test_a_run_paired_with_its_own_plan_ablation(planners_here):
    from pizero_ray.evaluation.runs import Search

    blind = compare_runs(planners_here["state"], planners_here["state"], 16, 0, search_b=Search(plan="shuffled"))
    assert blind["mean_difference"] == 0.0 and blind["share_tied"] == 1.0  # a decoder that cannot read the plan
    assert (blind["plan_a"], blind["plan_b"]) == ("intact", "shuffled")
    reading = compare_runs(planners_here["action"], planners_here["action"], 16, 0, search_b=Search(plan="shuffled"))
    assert reading["share_tied"] < 1.0
    assert "plan shuffled" in text_report(reading).splitlines()[1]


def test_a_run_paired_with_another_search_budget(planners_here, capsys):
    code, out, _ = _run(["compare", str(planners_here["action"]), str(planners_here["action"]), "--episodes", "8",
                         "--simulations-a", "1", "--json"], capsys)
    result = json.loads(out)
    assert code == 0 and (result["simulations_a"], result["simulations_b"]) == (1, 2)  # tiny's budget is 2


def test_eval_plan_ablation_reports_what_the_plan_is_worth(planners_here):
    blind = evaluate_run(planners_here["state"], 16, 0, plan="shuffled")
    assert blind["plan_difference"] == 0.0 and blind["share_actions_changed"] == 0.0
    assert blind["share_episodes_unchanged"] == 1.0 and blind["mean_score"] == blind["intact_mean_score"]
    reading = evaluate_run(planners_here["action"], 16, 0, plan="zeroed", simulations=1)
    assert reading["share_actions_changed"] > 0 and reading["simulations"] == 1 and reading["plan"] == "zeroed"


def test_the_plan_ablation_is_refused_where_there_is_no_plan(runs_here, capsys):
    code, _, err = _run(["eval", str(runs_here["untrained"]), "--plan", "shuffled", "--episodes", "4"], capsys)
    assert code == 2 and len(err) == 1 and "no plan to ablate" in err[0], err
    code, _, err = _run(["eval", str(runs_here["untrained"]), "--simulations", "3", "--episodes", "4"], capsys)
    assert code == 2 and len(err) == 1 and "has no planner" in err[0], err
