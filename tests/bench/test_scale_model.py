"""The scale model's arithmetic: what each design moves and where the driver saturates."""

import pytest

from pizero_ray.bench import scale_model

COSTS = scale_model.UnitCosts(driver_per_chunk_s=1e-3, bytes_per_s=1e9, put_bytes_per_s=4e9,
                              part_s={1000: 1e-5, 10_000: 1e-4}, adam_s={1000: 1e-4}, add_part_s={1000: 1e-6})


def test_a_rollout_that_outlasts_the_driver_runs_at_the_efficiency_of_its_fixed_costs():
    # 8 workers, 16 chunks of 100 pairs at 1,000 steps/s: 4 s of rollout, 16 ms of chunk handling.
    row = scale_model.iteration(COSTS, "a_parts_on_workers", 8, 16, 100, 1000, 1000.0)
    assert row["compute_s"] == pytest.approx(16 * 100 * 20 / 8000)
    update = 16 * (4000 / 1e9 + 1e-6) + 1e-4
    broadcast = 4000 / 4e9 + 1 * 4000 / 1e9  # one node
    assert row["iteration_s"] == pytest.approx(4.0 + update + broadcast)
    assert row["bytes_to_driver"] == 16 * 100 * 8 + 16 * 4000 and row["bytes_to_workers"] == 4000


def test_the_driver_bounds_an_iteration_once_it_hands_out_chunks_slower_than_workers_eat_them():
    workers = scale_model.saturation_workers(COSTS, pairs_per_chunk=100, rate_per_worker=1000.0)
    assert workers == pytest.approx(100 * 20 / (1000.0 * 1e-3))
    chunks = 4 * int(workers)
    at = scale_model.iteration(COSTS, "b_replayed", int(workers), chunks, 100, 1000, 1000.0)
    assert at["compute_s"] == pytest.approx(chunks * 1e-3)  # rollout and chunk handling take as long
    beyond = scale_model.iteration(COSTS, "b_replayed", 4 * int(workers), chunks, 100, 1000, 1000.0)
    assert beyond["compute_s"] < at["compute_s"] and beyond["efficiency"] < at["efficiency"]


def test_replayed_updates_move_only_scores_and_pay_the_whole_update_on_every_worker():
    row = scale_model.iteration(COSTS, "b_replayed", 16, 32, 100, 10_000, 1000.0)
    assert row["bytes_to_workers"] == 2 * 32 * 100 * 8  # two nodes of 8, the scores each
    on_driver = scale_model.iteration(COSTS, "a_parts_on_driver", 16, 32, 100, 10_000, 1000.0)
    assert row["bytes_to_workers"] < on_driver["bytes_to_workers"] == 2 * 40_000
    every_part, adam_at_10k = 32 * 100 * 1e-4, 1e-4 * 10  # 1e-4 s a pair at 10,000 parameters; Adam linear in D
    assert row["iteration_s"] - row["compute_s"] == pytest.approx(every_part + adam_at_10k + 2 * 32 * 100 * 8 / 1e9)


def test_per_parameter_costs_grow_linearly_beyond_the_largest_measured():
    assert scale_model._at({1000: 2.0, 10_000: 5.0}, 100_000) == pytest.approx(50.0)
    assert scale_model._at({1000: 2.0, 10_000: 5.0}, 10_000) == 5.0
