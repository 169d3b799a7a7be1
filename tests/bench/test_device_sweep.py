"""The population sweep (pizero_ray.bench.population_sweep): a row per point, timed, and errors kept in their row."""

import pytest

from pizero_ray.bench import population_sweep as sweep

TINY = {"hidden_size": 8, "latent_size": 8, "memory_size": 8, "num_abstract_actions": 2}
TSP_HORIZON = 10  # TSP10: every episode runs to it


@pytest.fixture(scope="module")
def rows():
    points = [
        sweep.SweepPoint(population=4, mode="low_rank", simulations=2, chunk_size=2, overrides=TINY),
        {"population": 4, "simulations": 2, "chunk_size": 2, "overrides": {**TINY, "hidden_size": -3}},
        {"population": 2, "mode": "exact", "planner": "none", "simulations": 2, "chunk_size": 4, "overrides": TINY},
        {"population": 2, "mode": "sideways", "simulations": 2, "chunk_size": 2, "overrides": TINY},
    ]
    said = []
    measured = sweep.population_sweep(points, repeats=2, progress=said.append)
    assert len(said) == len(points) and said[0].startswith("population sweep: 4 pairs, low_rank, muzero, 2 sims")
    return measured


def test_each_point_is_timed_as_a_whole_population_on_one_device(rows):
    low_rank, _, exact, _ = rows
    for row, population, chunk in ((low_rank, 4, 2), (exact, 2, 2)):  # exact: the chunk follows the population
        assert set(sweep.ROW_FIELDS) <= set(row) and "error" not in row
        assert (row["population"], row["chunk_size"], row["chunks"]) == (population, chunk, population // chunk)
        assert row["platform"] == "cpu" and row["device_memory_bytes"] is None  # the CPU reports no memory stats
        assert row["compile_s"] > 0 and row["warmup_s"] > 0 and len(row["iteration_s_each"]) == 2
        assert row["iteration_s"] == pytest.approx(sorted(row["iteration_s_each"])[0] / 2
                                                   + sorted(row["iteration_s_each"])[1] / 2)
        # every member plays one TSP10 episode to its horizon
        assert row["agent_steps_per_s"] * row["iteration_s"] == pytest.approx(population * 2 * TSP_HORIZON)
        assert row["overrides"] == TINY
        # the whole population in one device call
        assert (row["chunks_per_launch"], row["device_calls_per_iteration"]) == (population // chunk, 1)
    assert (low_rank["mode"], low_rank["planner"], exact["mode"], exact["planner"]) == (
        "low_rank", "muzero", "exact", "none")


def test_each_row_holds_its_programs_loops(rows):
    low_rank, _, no_planner, _ = rows
    assert "2[" in low_rank["program_loops"]["data_dependent_loop_shape"]  # mctx's loop over 2 simulations
    assert "[" not in no_planner["program_loops"]["data_dependent_loop_shape"]  # the episode loop alone
    assert low_rank["program_loops"]["while_loops"] > no_planner["program_loops"]["while_loops"] >= 1


def test_a_point_that_fails_records_its_error_and_the_sweep_goes_on(rows):
    _, bad_setting, measured_after, bad_mode = rows
    assert bad_setting["error"].startswith("ConfigError") and "-3" in bad_setting["error"]
    assert "agent_steps_per_s" not in bad_setting and bad_setting["population"] == 4
    assert measured_after["agent_steps_per_s"] > 0
    assert "unknown mode 'sideways'" in bad_mode["error"] and "\n" not in bad_mode["error"]
