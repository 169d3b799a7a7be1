"""scripts/device_run.py: its plan (pure), and its whole default path on the CPU at the smallest sizes."""

import importlib
import json
import subprocess
import sys

import pytest

from pizero_ray.bench.population_sweep import ROW_FIELDS, as_point
from pizero_ray.cli import training
from pizero_ray.cli.commands import build_parser
from pizero_ray.presets import PRESETS
from tests.scripts_loading import SCRIPTS


@pytest.fixture(scope="module")
def device_run():
    with pytest.MonkeyPatch.context() as patch:
        patch.syspath_prepend(str(SCRIPTS))  # as `python3 scripts/device_run.py` has it: device_common beside it
        yield importlib.import_module("device_run")  # registered: its dataclasses need their module


def test_the_gpu_plan_sweeps_the_main_curve_and_varies_one_thing_at_a_time(device_run):
    plan = device_run.plan_for(device_run.parse_args([]))
    main, cross = device_run.sweep_points(plan)
    curve = [p for p in main if p["overrides"] == {} and p["planner"] == "muzero"]
    assert [p["population"] for p in curve] == [64, 256, 1024, 4096, 8192, 16384, 32768]
    assert {**curve[-1], "planner": "none"} in main  # the planner-free agent at the largest population
    assert all((p["mode"], p["planner"], p["simulations"], p["chunk_size"]) == ("low_rank", "muzero", 10, 256)
               for p in curve)
    assert device_run.trainer_point(plan) in main  # the rollout the trainer is held to
    base, *variants = cross
    assert base in main and base["population"] == 8192 and len(variants) >= 2
    for variant in variants:  # each cross section differs from its base in exactly one field
        assert variant["population"] == 8192
        assert len([key for key in base if base[key] != variant[key]]) == 1, variant
    assert {"exact", "none"} <= {v["mode"] for v in variants} | {v["planner"] for v in variants}


def test_the_command_line_sizes_win_over_the_plan(device_run):
    plan = device_run.plan_for(device_run.parse_args(["--cpu-rehearsal", "--chunk-size", "32",
                                                      "--trainer-iterations", "5"]))
    assert (plan.chunk_size, plan.trainer_iterations, plan.populations, plan.gpus_per_worker) == (32, 5, (16, 64), 0)
    for wrong in (["--repeats", "0"], ["--learn", "tsp", "--preset", "fastest"], ["--budget-s", "-1"]):
        with pytest.raises(SystemExit):
            device_run.parse_args(wrong)


def test_the_training_is_the_sweeps_trainer_point(device_run):
    plan = device_run.plan_for(device_run.parse_args([]))
    command = device_run.train_command("python", plan, device_run.Path("/tmp/run"), 2, 0.5, device_run.Path("/c"))
    flags = command[command.index("train") + 1:command.index("--no-progress")]
    given = dict(zip(flags[::2], flags[1::2]))
    assert (given["--population"], given["--chunk-size"], given["--chunks-per-call"]) == ("16384", "256", "32")
    assert (given["--hidden"], given["--simulations"], given["--perturbation-rank"], given["--planner"]) == (
        "64", "10", "1", "muzero")
    assert (given["--workers"], given["--gpus-per-worker"]) == ("2", "0.5")
    launch = device_run.trainer_point(plan)["overrides"].get("chunks_per_launch")
    assert given.get("--chunks-per-launch") == (None if launch is None else "32")  # two workers: a launch each
    assert launch == PRESETS["gpu"]["chunks_per_launch"]  # the gpu preset's launches
    # `pizero train` parses these options into the config step b times at this point
    args = build_parser().parse_args(command[command.index("train"):])
    assert training.train_config(args) == as_point(device_run.trainer_point(plan)).config()


def test_the_trainer_is_held_to_the_rollout_of_its_own_population(device_run):
    plan = device_run.plan_for(device_run.parse_args([]))
    point = device_run.trainer_point(plan)
    rows = [{**point, "mode": mode, "iteration_s": seconds} for mode, seconds in (("exact", 9.0), ("low_rank", 0.5))]
    assert device_run.main_rollout_row(rows, plan)["iteration_s"] == 0.5
    assert device_run.main_rollout_row(rows[:1], plan) is None
    assert device_run.main_rollout_row([{**rows[1], "error": "out of memory"}], plan) is None
    assert device_run.later_half_median([{"t": 9.0}, {"t": 1.0}, {"t": 2.0}, {"t": 4.0}], "t") == 3.0


@pytest.mark.slow
def test_the_smoke_run_measures_every_step(device_run, tmp_path):
    # About 55 s on a quiet 2-core machine (the size --smoke is made for); no time limit asserted: a busy one
    # (the suite's -n 2) is slower.
    done = subprocess.run([sys.executable, str(SCRIPTS / "device_run.py"), "--smoke", "--python", sys.executable,
                           "--out", str(tmp_path)], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    (path,) = tmp_path.glob("*-device-run-*.json")
    report = json.loads(path.read_text())
    assert report["gpu_tests"] == {"skipped": "CPU rehearsal"}
    sweep, buffers = report["population_sweep"]["rows"], report["population_sweep_command_buffers"]["rows"]
    main, _ = device_run.sweep_points(device_run.plan_for(device_run.parse_args(["--smoke"])))
    assert [(r["population"], r["planner"], r["overrides"]) for r in sweep] == [
        (p["population"], p["planner"], p["overrides"]) for p in main]
    assert [r["population"] for r in buffers] == [8]
    assert "--xla_gpu_enable_command_buffer" in report["population_sweep_command_buffers"]["xla_flags"]
    for row in sweep + buffers:
        assert "error" not in row and set(ROW_FIELDS) <= set(row), row
        assert row["agent_steps_per_s"] * row["iteration_s"] == pytest.approx(8 * 2 * 10)
    _check_trainer(report["trainer"], sweep[-1])
    assert report["targets"]["best_rollout_agent_steps_per_s"] == sweep[0]["agent_steps_per_s"]
    assert report["targets"]["hashes_equal_1_and_2_workers"] is True


def _check_trainer(trainer: dict, rollout: dict) -> None:
    one, two = trainer["one_worker"], trainer["two_workers"]
    for run, workers in ((one, 1), (two, 2)):
        assert (run["workers"], run["exit_code"], run["iterations"]) == (workers, 0, 2)
        assert len(run["parameter_hash"]) == 64 and 0 < run["update_share"] < 1
    assert trainer["hashes_equal"] is True and one["parameter_hash"] == two["parameter_hash"]
    assert trainer["rollout_iteration_s"] == rollout["iteration_s"]
    assert trainer["iteration_over_rollout"] == pytest.approx(one["median_iteration_s"] / rollout["iteration_s"])
