"""The benchmark's pieces compute what they claim (speed itself is not asserted: that is the bench's job)."""

import pytest

from pizero_ray.cli import bench
from pizero_ray.config import build_config


def test_rollout_measures_agent_steps_of_the_whole_population():
    config = build_config("tiny", population=4, chunk_size=2)
    result = bench.rollout(config, repeats=1)
    steps = 4 * 2 * 10  # pairs x members x TSP10 horizon
    assert result["agent_steps_per_s"] * result["iteration_s"] == pytest.approx(steps)
    assert result["simulations_per_s"] == pytest.approx(result["agent_steps_per_s"] * config.num_simulations)
    assert result["compile_s"] > 0
    assert result["devices"] == 2  # chunks dealt over both of the test process's CPU devices


def test_rollouts_can_keep_a_config_to_one_device():
    config = build_config("tiny", population=4, chunk_size=2)
    results = bench.rollouts({"all": config, "one": config}, repeats=1, max_devices={"one": 1})
    assert (results["all"]["devices"], results["one"]["devices"]) == (2, 1)


def test_traffic_is_parameters_and_weights_out_scores_and_gradient_parts_back():
    config = build_config("tiny", population=8, chunk_size=4)
    result = bench.traffic(config, parameters=1000)
    assert result["driver_to_workers_bytes_per_node"] == 4000
    assert result["driver_to_workers_weights_bytes"] > 2 * 16  # two chunks of four float32 weights, framed
    assert result["workers_to_driver_payload_bytes"] == 64 + 2 * 4000  # scores, and a part per chunk
    assert result["workers_to_driver_bytes"] > 64 + 2 * 4000  # plus framing


def test_bench_config_is_the_papers_agent():
    config = bench.bench_config(1000, 40)
    assert (config.hidden_size, config.latent_size, config.num_abstract_actions, config.num_simulations) == (
        64, 64, 4, 10)
    assert config.env == "tsp" and config.num_chunks == 25


def test_bench_chunks_divide_any_population():
    assert bench.bench_config(256, 40).chunk_size == 32
    assert bench.bench_config(64, 40).chunk_size == 32
    assert bench.bench_config(7, 40).chunk_size == 7
    assert bench.bench_config(64, 40, devices=4).chunk_size == 16  # every device gets a chunk
    assert bench.bench_config(1000, 250, devices=2).chunk_size == 250


def test_bench_modes_differ_only_in_the_perturbation_and_the_straightforward_search():
    exact = bench.bench_config(1000, 40)
    low_rank = bench.bench_config(1000, 100, perturbation_rank=bench.LOW_RANK)
    straightforward = bench.bench_config(1000, 40, root_noise=1e-9)
    assert (exact.perturbation_rank, low_rank.perturbation_rank) == (0, bench.LOW_RANK)
    assert low_rank.chunk_size == 100 and straightforward.root_noise > 0
    assert {k: v for k, v in vars(exact).items() if k not in ("perturbation_rank", "chunk_size", "root_noise")} == {
        k: v for k, v in vars(low_rank).items() if k not in ("perturbation_rank", "chunk_size", "root_noise")}
    assert bench.QUICK.low_rank_trainer_workers == () and set(bench.FULL.sweep_modes) == {"exact", "low_rank"}
    for plan in (bench.QUICK, bench.FULL):  # distributed efficiency needs the 2-worker run
        assert 2 in plan.exact_trainer_workers
