"""The scale model's arithmetic: what each design moves and where the driver saturates."""

import pytest

from pizero_ray.bench import scale_model

COSTS = scale_model.UnitCosts(driver_per_chunk_s=1e-3, bytes_per_s=1e9, put_bytes_per_s=4e9,
                              part_s={1000: 1e-5, 10_000: 1e-4}, adam_s={1000: 1e-4}, add_part_s={1000: 1e-6})


def test_a_rollout_that_outlasts_the_driver_runs_at_the_efficiency_of_its_fixed_costs():
    # 8 workers, 16 chunks of 100 pairs at 1,000 steps/s: seconds of rollout against milliseconds of handling.
    row = scale_model.iteration(COSTS, "a_parts_on_workers", 8, 16, 100, 1000, 1000.0)
    assert row["compute_s"] > 100 * (row["iteration_s"] - row["compute_s"])  # the rollout is nearly all of it
    assert 0.99 < row["efficiency"] < 1.0
    twice = scale_model.iteration(COSTS, "a_parts_on_workers", 16, 16, 100, 1000, 1000.0)
    assert twice["compute_s"] == pytest.approx(row["compute_s"] / 2)  # twice the workers, half the rollout
    # Parts come back: each chunk's part is a parameter vector, against 8 bytes of scores a pair.
    longer = scale_model.iteration(COSTS, "a_parts_on_workers", 8, 16, 200, 1000, 1000.0)
    assert longer["bytes_to_driver"] - row["bytes_to_driver"] == 16 * 100 * 8  # only the scores grow
    assert row["bytes_to_workers"] == twice["bytes_to_workers"] // 2  # the parameters once per node


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
    on_driver = scale_model.iteration(COSTS, "a_parts_on_driver", 16, 32, 100, 10_000, 1000.0)
    assert row["bytes_to_workers"] < on_driver["bytes_to_workers"]  # scores, not parameters
    bigger = scale_model.iteration(COSTS, "b_replayed", 16, 32, 100, 100_000, 1000.0)
    assert bigger["bytes_to_workers"] == row["bytes_to_workers"]  # whatever the parameter count
    assert bigger["update_s"] > 5 * row["update_s"]  # but every worker pays the update, growing with it
    assert row["driver_s"] < on_driver["driver_s"]  # which the driver does not


def test_per_parameter_costs_grow_linearly_beyond_the_largest_measured():
    assert scale_model._at({1000: 2.0, 10_000: 5.0}, 100_000) == pytest.approx(50.0)
    assert scale_model._at({1000: 2.0, 10_000: 5.0}, 10_000) == 5.0
