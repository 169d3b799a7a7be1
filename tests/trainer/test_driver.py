"""End to end: real Ray, real worker actors, tiny configs."""

import json
import math

import numpy as np
import pytest

import envs
from pizero_ray.cli import main
from pizero_ray.config import build_config
from pizero_ray.es import population
from pizero_ray.storage import run_dir, runs
from pizero_ray.trainer import driver


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


def _inspect(path, capsys):
    assert main(["inspect", str(path), "--json"]) == 0
    return json.loads(capsys.readouterr().out)


def test_two_workers_write_metrics_checkpoints_and_a_hash(two_iterations, tmp_path, capsys):
    path, result = two_iterations
    rows = run_dir.read_metrics(path)
    assert [row["iteration"] for row in rows] == [0, 1, 2]
    assert set(rows[0]) == {"iteration", "eval_mean_score", "wall_time_s"}  # the untrained agent
    for row in rows[1:]:
        assert 1 <= row["workers"] <= 2 and row["mean_score"] < 0 and "eval_mean_score" in row
        assert row["wall_time_s"] > 0
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
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


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

    import envs
    from pizero_ray import es
    from pizero_ray.es import population

    trained_path, trained = two_iterations
    config = build_config("tiny")
    env = envs.make(config.env, **config.env_kwargs())
    theta, layout = population.flat_params(config, env)
    evaluate = population.make_pair_evaluator(config, env, layout)
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
    state, layout, _ = runs.initial_state(wider, runs.make_env(wider))
    with pytest.raises(ConfigError, match=r"--init-from .* does not fit this run's \(\d+ parameters\)"):
        runs.warm_start(state, layout, source)


def test_init_from_a_missing_run_is_a_one_line_error_and_writes_nothing(tmp_path, capsys):
    args = ["train", "--preset", "tiny", "--run-dir", str(tmp_path / "run"), "--init-from", str(tmp_path / "none")]
    assert main(args) == 2
    assert f"run dir {tmp_path / 'none'} does not exist" in capsys.readouterr().err
    assert not (tmp_path / "run").exists()


def test_a_wall_clock_budget_stops_with_a_checkpoint_and_resume_raises_it(ray_session, tmp_path, compile_cache_dir):
    config = build_config("tiny", planner="none")  # the budget is the driver's; the agent is the cheapest to start
    path = tmp_path / "budget"
    run_dir.write_config(path, config)

    def train(seconds):
        minutes = seconds / 60
        while 60.0 * minutes < seconds:  # the round trip can fall an ulp short; the budget must cover `seconds`
            minutes = math.nextafter(minutes, math.inf)
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
    assert runs.load_run(path).iteration == first["iteration"]  # checkpointed where it stopped
    evaluated_at_every_second(rows)

    spent = rows[-1]["wall_time_s"]
    again, _ = train(spent)  # the run's budget is spent: nothing more
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
