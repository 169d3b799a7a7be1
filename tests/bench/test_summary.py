"""The report names each figure for what it measures: speed-ups over the rollout they say, the keys readers use."""

import pytest

from pizero_ray.bench import summary


def _measurements(rollouts: dict) -> summary.Measurements:
    trainer = {"iteration_s": 2.0, "update_s": 0.5, "worker_first_result_s": 3.0, "gradient_on": "workers",
               "bytes_to_workers": 1000, "bytes_from_workers": 2000}
    timed = {name: {"agent_steps_per_s": rate, "simulations_per_s": 10 * rate, "iteration_s": 1.0, "compile_s": 1.0,
                    "parameters": 100} for name, rate in rollouts.items()}
    return summary.Measurements(
        device="cpu:0", device_kind="cpu", devices=2, worker_gpus=0.0, population=4, low_rank_chunk_size=2,
        rollouts=timed, driver_update_s={"exact": 0.1, "low_rank": 0.1}, sweeps={"simulations": [], "population": []},
        planners=[], trainers={("exact", 2): trainer}, cold_trainer=trainer, cached_trainer=trainer,
        cpus_per_worker={2: 1}, worker_peak_rss_mb={"exact": 1.0}, peak_rss_mb=1.0)


def test_speedups_are_over_the_rollout_their_name_says():
    result = summary.result(_measurements({"exact": 60.0, "exact_one_device": 40.0, "low_rank": 120.0,
                                          "straightforward": 20.0, "one_device_with_dirichlet_draw": 30.0}))
    assert result["speedup_vs_straightforward"] == pytest.approx(3.0)  # the plain rollout
    assert result["speedup_vs_straightforward_one_device"] == pytest.approx(2.0)
    assert result["speedup_vs_straightforward_low_rank"] == pytest.approx(6.0)
    assert result["speedup_vs_one_device_with_dirichlet_draw"] == pytest.approx(2.0)
    assert result["straightforward_agent_steps_per_s"] == 20.0
    assert result["one_device_with_dirichlet_draw_agent_steps_per_s"] == 30.0


def test_a_plan_without_the_baselines_reports_no_speedups_and_the_keys_readers_use():
    result = summary.result(_measurements({"exact": 60.0, "low_rank": 120.0}))
    assert not [key for key in result if key.startswith(("speedup_vs", "straightforward", "one_device_with"))]
    # scripts/device_check.py and docs/performance.md read these
    for key in ("rollout_agent_steps_per_s", "trainer_iteration_s_2_workers", "trainer_bytes_to_workers",
                "trainer_bytes_from_workers", "trainer_gradient_on", "compile_s", "worker_first_result_s_cold"):
        assert key in result
