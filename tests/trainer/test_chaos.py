"""`pizero chaos`'s runs, without Ray: where the kills fall, and what the two runs are given and compared on.

The end-to-end command (real workers SIGKILLed) is test_pool.py's test_chaos_command_reports_identical_hashes.
"""

from pizero_ray.config import build_config
from pizero_ray.storage import run_dir
from pizero_ray.trainer import chaos, driver
from pizero_ray.trainer.options import RunOptions

CONFIG = build_config("tiny", population=8, planner="none")  # 4 chunks of 2 pairs


def test_the_kill_schedule_is_a_function_of_the_seed():
    schedule = chaos.kill_schedule(seed=3, kills=5, iterations=4, num_chunks=4)
    assert schedule == chaos.kill_schedule(seed=3, kills=5, iterations=4, num_chunks=4)
    assert len(schedule) == 5 and all(0 <= i < 4 and 0 <= c < 4 for i, c in schedule)
    assert chaos.kill_schedule(seed=0, kills=9, iterations=2, num_chunks=2) == {(0, 0), (0, 1), (1, 0), (1, 1)}


def test_the_chaos_run_alone_gets_the_kills_and_the_hashes_are_compared(tmp_path, monkeypatch):
    trained = {}

    def fake_train(path, config, options):  # what each run would end with; the kills decide the hash here
        trained[path.name] = options
        assert run_dir.read_config(path) == config  # written before the run starts
        return {"parameter_hash": "h", "workers_killed": len(options.pool.kill_schedule)}

    monkeypatch.setattr(driver, "train", fake_train)
    started = []
    report = chaos.compare_runs(tmp_path, CONFIG, RunOptions.create(iterations=3), kills=2, seed=1,
                                on_run=lambda name, path: started.append((name, path)))
    assert started == [("clean", tmp_path / "clean"), ("chaos", tmp_path / "chaos")]
    assert trained["clean"].pool.kill_schedule == frozenset()
    assert trained["chaos"].pool.kill_schedule == chaos.kill_schedule(1, 2, 3, CONFIG.num_chunks)
    assert report == {"iterations": 3, "workers_killed": 2, "clean_parameter_hash": "h",
                      "chaos_parameter_hash": "h", "identical": True}
