"""Stub workers: the real driver and pool run against them, and the result does not depend on how they stand in."""

import numpy as np

from pizero_ray.bench.stub_workers import StubWorkers, stub_scores
from pizero_ray.config import build_config
from pizero_ray.storage import run_dir
from pizero_ray.trainer import driver

CONFIG = build_config("tiny", population=16, chunk_size=2, planner="none")  # 8 chunks


def _train(path, stubs, workers, config=CONFIG, iterations=3, kill_schedule=frozenset(), chunks_per_call=1):
    run_dir.write_config(path, config)
    options = driver.RunOptions.create(iterations=iterations, workers=workers, checkpoint_every=0,
                                       gradient_on="driver", compile_cache="none", chunks_per_call=chunks_per_call,
                                       kill_schedule=kill_schedule)
    try:
        result = driver.train(path, config, options, worker_factory=stubs.factory())
    finally:
        stubs.shutdown()
    return result, [row for row in run_dir.read_metrics(path) if row["iteration"] > 0]


def test_scores_are_a_function_of_seed_and_pairs_and_untied():
    scores = stub_scores(7, 4, 3)
    np.testing.assert_array_equal(scores, stub_scores(7, 4, 3))
    assert scores.shape == (3, 2) and len(np.unique(scores)) == 6
    assert not np.array_equal(scores, stub_scores(7, 6, 3)) and not np.array_equal(scores, stub_scores(8, 4, 3))


def test_workers_in_processes_of_their_own_or_standing_in_give_the_same_parameters(ray_session, tmp_path):
    own, own_rows = _train(tmp_path / "own", StubWorkers(CONFIG.chunk_size, 100, 0.01), workers=2)
    stand_ins = StubWorkers(CONFIG.chunk_size, 100, 0.01, processes=2)
    shared, shared_rows = _train(tmp_path / "shared", stand_ins, workers=6)
    assert own["parameter_hash"] == shared["parameter_hash"]
    assert all(row["pairs_evaluated"] == CONFIG.population for row in own_rows + shared_rows)
    assert stand_ins.started == 6 and len(stand_ins._actors) == 2  # six workers on two processes


def test_a_tenth_of_the_workers_killed_in_every_iteration_changes_nothing(ray_session, tmp_path):
    """Twenty stub workers, each in a process of its own; in each of three iterations two of them are SIGKILLed
    right after taking a chunk (`bench --scale` does this with 96 workers and times it)."""
    config = build_config("tiny", population=80, chunk_size=2, planner="none")  # 40 chunks
    clean, _ = _train(tmp_path / "clean", StubWorkers(2, 100, 0.02), 20, config)
    schedule = frozenset((iteration, chunk) for iteration in range(3) for chunk in (5, 23))
    killed, rows = _train(tmp_path / "killed", StubWorkers(2, 100, 0.02), 20, config, kill_schedule=schedule)
    assert killed["workers_killed"] == 6 and sum(row["workers_lost"] for row in rows) == 6
    assert all(row["pairs_evaluated"] == config.population for row in rows)  # every iteration completed
    assert killed["parameter_hash"] == clean["parameter_hash"]
    batched, rows = _train(tmp_path / "batched", StubWorkers(2, 100, 0.02), 20, config, kill_schedule=schedule,
                           chunks_per_call=4)  # a kill takes a call of four chunks with it
    assert batched["parameter_hash"] == clean["parameter_hash"] and batched["workers_killed"] == 6
    assert all(row["pairs_evaluated"] == config.population for row in rows)
