"""End to end: real Ray, real worker actors, tiny configs."""

import json
import math

import numpy as np
import pytest

from pizero_ray import envs, methods
from pizero_ray.cli import main
from pizero_ray.config import build_config
from pizero_ray.es import population
from pizero_ray.storage import run_dir, runs
from pizero_ray.trainer import driver
from tests.figures import assert_curves_drawn


def _train(path, iterations, workers, compile_cache_dir, cpus_per_worker=1.0, eval_every=1, **overrides):
    """``eval_every=0`` where a test compares only parameters: the driver's evaluator is traced afresh each run."""
    config = build_config("tiny", **overrides)
    run_dir.write_config(path, config)
    options = driver.RunOptions.create(iterations=iterations, workers=workers, compile_cache=compile_cache_dir,
                                       checkpoint_every=3, eval_every=eval_every, eval_episodes=8,
                                       cpus_per_worker=cpus_per_worker)
    return driver.train(path, config, options)


@pytest.fixture(scope="module")
def two_iterations(ray_session, tmp_path_factory, compile_cache_dir):
    """(run dir, result) of two iterations on two workers, checkpointed every 3: the last checkpoint is the one
    a run saves where it ends. Tests read it, none changes it."""
    path = tmp_path_factory.mktemp("two-iterations") / "run"
    return path, _train(path, 2, 2, compile_cache_dir)


def _held_out_optimal_tour(config, episodes: int) -> float:
    """The mean optimal (Held-Karp) tour of the TSP instances the driver's learning curve is evaluated on."""
    import jax

    from pizero_ray.agent.episodes import episode_reset_keys
    from pizero_ray.envs import tsp

    env = envs.make(config.env, **config.env_kwargs())
    states, _ = jax.vmap(env.reset)(episode_reset_keys(jax.random.PRNGKey(driver.EVAL_SEED), episodes))
    return float(tsp.optimal_tour_length(np.asarray(states.coordinates)).mean())


def _inspect(path, capsys):
    assert main(["inspect", str(path), "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_two_workers_write_metrics_checkpoints_and_a_hash(two_iterations, tmp_path, capsys):
    path, result = two_iterations
    rows = run_dir.read_metrics(path)
    assert [row["iteration"] for row in rows] == [0, 1, 2]
    # The untrained agent, and what its plan is worth (the shuffled plan's score, the actions it changes)
    assert set(rows[0]) == {"iteration", "eval_mean_score", "eval_plan_shuffled_score", "eval_plan_actions_changed",
                            "wall_time_s"}
    assert 0 <= rows[0]["eval_plan_actions_changed"] <= 1
    config = run_dir.read_config(path)
    # A score is minus one closed tour through the cities (one step each: the horizon) in the unit square, each
    # leg at most its diagonal.
    longest_tour = envs.make(config.env, **config.env_kwargs()).spec.horizon * math.sqrt(2)
    for row in rows[1:]:
        assert 1 <= row["workers"] <= 2 and "eval_mean_score" in row
        assert -longest_tour <= row["min_score"] <= row["mean_score"] <= row["max_score"] < 0, row
        assert row["wall_time_s"] > 0
    optimal = _held_out_optimal_tour(config, episodes=8)  # no agent's tours beat it on the same instances
    for row in rows:  # (1e-4: the scores are float32 sums)
        assert optimal - 1e-4 <= -row["eval_mean_score"] <= longest_tour, (row, optimal)
    info = _inspect(path, capsys)
    assert info["iteration"] == 2 and info["parameter_hash"] == result["parameter_hash"]
    assert info["checkpoints"] == [0, 2]  # 0: saved before the first iteration; 2: where the run ended
    untrained = runs.parameter_hash(np.asarray(population.flat_params(build_config("tiny"), envs.make("tsp"))[0]))
    assert info["parameter_hash"] != untrained  # two updates moved the parameters

    assert main(["eval", str(path), "--episodes", "16", "--seed", "1", "--json"]) == 0
    evaluation = json.loads(capsys.readouterr().out)
    assert evaluation["env"] == "tsp" and evaluation["iteration"] == 2 and evaluation["episodes"] == 16
    low, high = evaluation["ci95"]
    assert low <= evaluation["mean_score"] <= high
    assert evaluation["mean_tour_length"] == pytest.approx(-evaluation["mean_score"])
    assert evaluation["ratio_to_optimal"] >= 1.0
    assert main(["eval", str(path), "--episodes", "16", "--seed", "1", "--json", "--zero-memory"]) == 0
    forgetful = json.loads(capsys.readouterr().out)
    assert forgetful["memory"] == "zeroed" and "memory" not in evaluation
    assert forgetful["mean_score"] != evaluation["mean_score"]  # the same parameters, without what they remember

    gif = tmp_path / "episode.gif"
    assert main(["render", str(path), "--out", str(gif)]) == 0
    from PIL import Image

    with Image.open(gif) as image:
        assert image.n_frames == 11  # the initial state and one frame per step of TSP10

    assert main(["eval", str(path), "--episodes", "4", "--env-arg", "num_cities=12"]) == 2
    assert "change the environment's shapes" in capsys.readouterr().err

    out = tmp_path / "curve.png"
    assert main(["plot", str(path), "--out", str(out)]) == 0
    # 11 x 4 inches at 110 dpi; the run's one curve in both panels (against iteration, against minutes)
    assert_curves_drawn(out, size=(1210, 440), panels=[("C0",)] * 2)


def test_worker_count_and_a_resume_do_not_change_the_result(two_iterations, tmp_path, compile_cache_dir):
    """Three iterations three ways: straight on three workers; straight on one worker with 2 CPUs, which runs
    two JAX CPU devices, a chunk on each at once; and the module's two iterations on two workers, resumed for
    the third on one worker. (One worker with one device: test_pool.py's reference run.) No evaluations: they
    leave the parameters alone, and the driver traces its evaluator afresh each run."""
    import shutil

    three = _train(tmp_path / "three", 3, 3, compile_cache_dir, eval_every=0)
    two_devices = _train(tmp_path / "two-devices", 3, 1, compile_cache_dir, cpus_per_worker=2.0, eval_every=0)
    path = tmp_path / "split"
    shutil.copytree(two_iterations[0], path)  # a run stopped after two of the three iterations
    options = driver.RunOptions.create(iterations=3, workers=1, compile_cache=compile_cache_dir, checkpoint_every=3)
    resumed = driver.train(path, run_dir.read_config(path), options)
    assert three["parameter_hash"] == two_devices["parameter_hash"] == resumed["parameter_hash"]
    assert [row["iteration"] for row in run_dir.read_metrics(path)] == [0, 1, 2, 3]


def test_gradient_parts_from_workers_equal_the_update_in_one_process(two_iterations):
    """Workers return each chunk's share from the noise they kept; the driver's own path regenerates it."""
    import jax.numpy as jnp

    from pizero_ray import envs, es
    from pizero_ray.es import population

    trained_path, trained = two_iterations
    config = build_config("tiny")
    env = envs.make(config.env, **config.env_kwargs())
    theta, layout = population.flat_params(config, env)
    evaluate = population.make_pair_scorer(config, env, layout)
    strategy = es.make_strategy(config, layout.perturbation)
    state = strategy.init(theta)
    valid = np.ones(config.population, bool)
    for _ in range(2):
        seed = strategy.ask(state)
        scores = np.concatenate([
            np.asarray(evaluate(state.theta, np.uint32(seed), jnp.arange(first, first + config.chunk_size),
                                strategy.parts.noise(np.uint32(seed), np.int32(first))))
            for first in range(0, config.population, config.chunk_size)])
        weights = strategy.weights(scores, valid)
        parts = [strategy.parts.chunk_here(seed, weights, index) for index in range(config.num_chunks)]
        state, _ = strategy.tell(state, scores, valid, parts)
    assert state.iteration == 2
    assert runs.parameter_hash(np.asarray(state.theta)) == trained["parameter_hash"]
    rows = run_dir.read_metrics(trained_path)
    assert [row["gradient_parts_on_driver"] for row in rows[1:]] == [0, 0]  # every part came from a worker


def test_init_from_starts_where_the_other_run_stands(two_iterations, tmp_path, compile_cache_dir):
    from pizero_ray.config import ConfigError

    source, _ = two_iterations
    _train(tmp_path / "next", 1, 1, compile_cache_dir, init_from=str(source))
    rows, source_rows = run_dir.read_metrics(tmp_path / "next"), run_dir.read_metrics(source)
    # Row 0 evaluates the starting parameters on the same held-out episodes: the source's last, not its first.
    assert rows[0]["eval_mean_score"] == source_rows[-1]["eval_mean_score"] != source_rows[0]["eval_mean_score"]
    assert [row["iteration"] for row in rows] == [0, 1]  # a run of its own, from iteration 0

    wider = build_config("tiny", hidden_size=16)
    state, layout, _ = methods.initial_state(wider, methods.make_env(wider))
    with pytest.raises(ConfigError, match=r"--init-from .* does not fit this run's \(\d+ parameters\)"):
        methods.warm_start(state, layout, source)


def test_init_from_a_missing_run_is_a_one_line_error_and_writes_nothing(tmp_path, capsys):
    args = ["train", "--preset", "tiny", "--run-dir", str(tmp_path / "run"), "--init-from", str(tmp_path / "none")]
    assert main(args) == 2
    assert f"run dir {tmp_path / 'none'} does not exist" in capsys.readouterr().err
    assert not (tmp_path / "run").exists()


def test_a_wall_clock_budget_stops_with_a_checkpoint_and_resume_raises_it(ray_session, tmp_path, compile_cache_dir):
    config = build_config("tiny", planner="none")  # the budget is the driver's; the agent is the cheapest to start
    path = tmp_path / "budget"
    run_dir.write_config(path, config)

    def train(seconds, at_most=False):
        # seconds / 60 * 60 can land an ulp either side of `seconds`: the budget must cover `seconds`, or, for a
        # budget already spent (``at_most``), not pass it
        minutes = seconds / 60
        while 60.0 * minutes < seconds:
            minutes = math.nextafter(minutes, math.inf)
        while at_most and 60.0 * minutes > seconds:
            minutes = math.nextafter(minutes, -math.inf)
        options = driver.RunOptions.create(minutes=minutes, workers=1, compile_cache=compile_cache_dir,
                                           checkpoint_every=0, eval_every=1000, eval_every_minutes=1 / 60,
                                           eval_episodes=4)
        return driver.train(path, config, options), run_dir.read_metrics(path)

    def evaluated_at_every_second(rows):
        """--eval-every-minutes 1/60: the first iteration past each whole second of training is evaluated."""
        for second in range(1, int(rows[-1]["wall_time_s"]) + 1):
            first = next(row for row in rows if row["wall_time_s"] >= second)
            assert "eval_mean_score" in first, (second, first["iteration"])

    first, rows = train(3.0)
    assert first["out_of_time"] and first["stopped_by"] is None and first["iteration"] >= 1
    assert rows[-1]["iteration"] == first["iteration"] and "eval_mean_score" in rows[-1]  # the last one is evaluated
    assert rows[-1]["wall_time_s"] >= 3.0 > rows[-2]["wall_time_s"]  # stopped by the first iteration past it
    assert methods.load_run(path).iteration == first["iteration"]  # checkpointed where it stopped
    evaluated_at_every_second(rows)

    spent = rows[-1]["wall_time_s"]
    again, _ = train(spent, at_most=True)  # the run's budget is spent: nothing more
    assert again["iteration"] == first["iteration"] and again["out_of_time"]
    more, later = train(spent + 4.0)  # four more seconds in all
    assert more["iteration"] > first["iteration"] and more["out_of_time"]
    assert later[-1]["wall_time_s"] >= spent + 4.0 > later[-2]["wall_time_s"]
    assert [row["iteration"] for row in later] == list(range(more["iteration"] + 1))
    evaluated_at_every_second(later)  # the marks carry on across the resume

    spent = later[-1]["wall_time_s"]
    last, rows = train(spent + 1e-6)  # as a run killed a moment short of its budget: one more iteration, evaluated
    assert last["iteration"] == more["iteration"] + 1 and "eval_mean_score" in rows[-1]


def test_a_run_needs_a_target_and_a_positive_budget(tmp_path, capsys):
    path = tmp_path / "run"
    run_dir.write_config(path, build_config("tiny"))
    assert main(["resume", str(path)]) == 2
    err = capsys.readouterr().err
    assert "--iterations N" in err and "--minutes M" in err
    assert main(["train", "--run-dir", str(tmp_path / "x"), "--minutes", "0"]) == 2
    assert "--minutes must be positive, got 0" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()  # nothing written


NAN_CONFIG = build_config("tiny", population=8, planner="none")  # 4 chunks; fake workers score them (no JAX)


def test_an_environment_that_scores_nan_everywhere_stops_the_run_in_one_line(
        tmp_path, monkeypatch, ray_session, compile_cache_dir, capsys):
    """No finite score is left to learn from: the run stops, naming the iteration and a member, before the
    update; the checkpoint of iteration 0 stands."""
    from tests.trainer import fake_workers

    fake_workers.use(monkeypatch, NAN_CONFIG, scores=lambda seed, first, chunk: np.full((chunk, 2), np.nan))
    code = main(["train", "--run-dir", str(tmp_path), "--preset", "tiny", "--population", "8", "--planner", "none",
                 "--iterations", "3", "--workers", "1", "--compile-cache", compile_cache_dir, "--no-progress"])
    errors = capsys.readouterr().err.strip().splitlines()
    assert code == 1
    assert errors[-1] == ("pizero: error: iteration 1: no member scored a finite score (pair 0's +sigma member "
                          "scored nan); check the environment's rewards")
    assert methods.load_run(tmp_path).iteration == 0 and run_dir.read_metrics(tmp_path) == []


def test_a_member_scoring_nan_ranks_last_is_counted_and_warned_of(tmp_path, monkeypatch, ray_session,
                                                                  compile_cache_dir, caplog):
    from tests.trainer import fake_workers

    def one_broken(seed, first_pair, chunk):
        scores = fake_workers.untied_scores(seed, first_pair, chunk)
        if first_pair == 2:
            scores[1, 0] = np.nan  # pair 3's +sigma member, every iteration
        return scores

    fake_workers.use(monkeypatch, NAN_CONFIG, scores=one_broken)
    run_dir.write_config(tmp_path, NAN_CONFIG)
    options = driver.RunOptions.create(iterations=2, workers=1, checkpoint_every=0, compile_cache=compile_cache_dir,
                                       gradient_on="driver")
    with caplog.at_level("WARNING", logger="pizero_ray.trainer.driver"):
        driver.train(tmp_path, NAN_CONFIG, options)
    rows = [row for row in run_dir.read_metrics(tmp_path) if row["iteration"] > 0]
    assert [row["non_finite_scores"] for row in rows] == [1, 1]
    assert all(math.isfinite(row[key]) for row in rows for key in ("mean_score", "min_score", "update_norm"))
    assert np.isfinite(methods.load_run(tmp_path).theta).all()
    warnings = [record.getMessage() for record in caplog.records]
    assert warnings[0] == ("pizero: warning: iteration 1: 1 member(s) scored NaN or infinity and rank last "
                           "(pair 3's +sigma member scored nan)")


def test_a_baseline_whose_rewards_are_nan_stops_before_keeping_the_parameters(tmp_path, monkeypatch):
    """AlphaZero learns in the driver's process: a NaN reward would reach its loss and, from there, every
    parameter. The run stops at the first such iteration instead, one line naming what is not finite."""
    config = build_config("tiny", method="alphazero", env="tsp")
    real_make_env = methods.make_env

    def nan_rewards(config, **env_args):
        env = real_make_env(config, **env_args)

        def step(state, action):
            state, observation, reward, done = env.step(state, action)
            return state, observation, reward * np.nan, done

        return env._replace(step=step)

    monkeypatch.setattr(methods, "make_env", nan_rewards)
    run_dir.write_config(tmp_path, config)
    with pytest.raises(driver.TrainingError, match=r"^iteration 1: the self-play score, loss, .* is not finite"):
        driver.train(tmp_path, config, driver.RunOptions.create(iterations=2, checkpoint_every=0))
    assert methods.load_run(tmp_path).iteration == 0  # the parameters trained on NaN were never kept
