"""The elastic pool: workers die, nodes come and go, stragglers hang; the parameters stay bit-identical."""

import dataclasses

import pytest

from pizero_ray import methods
from pizero_ray.config import build_config
from pizero_ray.storage import run_dir
from pizero_ray.trainer import driver
from tests.conftest import OBJECT_STORE_BYTES
from tests.trainer import fake_workers

ITERATIONS = 4
# 4 chunks of 2 pairs per iteration. No planner: what is checked here is the pool (faults, nodes, stragglers),
# and each worker it starts traces and compiles the agent; without the search that is a third of the work.
# The planner's agent across workers is test_driver.py's and test_chunk_scoring.py's.
CONFIG = build_config("tiny", population=8, planner="none")


def _train(path, compile_cache_dir, on_iteration=None, config=CONFIG, on_start=None, **options):
    run_dir.write_config(path, config)
    options = {"workers": 2, "checkpoint_every": 0, **options}
    options = driver.RunOptions.create(iterations=ITERATIONS, compile_cache=compile_cache_dir, **options)
    result = driver.train(path, config, options, on_iteration=on_iteration, on_start=on_start)
    return result, [row for row in run_dir.read_metrics(path) if row["iteration"] > 0]


@pytest.fixture(scope="module")
def reference_hash(ray_session, tmp_path_factory, compile_cache_dir):
    result, _ = _train(tmp_path_factory.mktemp("reference"), compile_cache_dir, workers=1)
    return result["parameter_hash"]


def test_parts_formed_on_the_driver_give_the_same_parameters(tmp_path, compile_cache_dir, reference_hash):
    # Two workers against the reference's one. With the parts formed on the workers, the default, two workers
    # are test_sigkilled_workers_mid_iteration's (its kills aside); other worker counts are test_driver.py's.
    result, rows = _train(tmp_path, compile_cache_dir, gradient_on="driver")
    assert result["parameter_hash"] == reference_hash
    assert all(row["pairs_evaluated"] == CONFIG.population for row in rows)
    assert all(row["gradient_parts_on_driver"] == CONFIG.num_chunks for row in rows)  # no worker was asked


def test_several_chunks_per_call_give_the_same_parameters(tmp_path, compile_cache_dir, reference_hash):
    result, rows = _train(tmp_path, compile_cache_dir, chunks_per_call=3)  # 4 chunks: calls of 3 and 1
    assert result["parameter_hash"] == reference_hash
    assert all(row["pairs_evaluated"] == CONFIG.population for row in rows)


def test_low_rank_parts_of_a_call_formed_together_on_the_workers_equal_the_drivers(tmp_path, compile_cache_dir):
    """Rank-1 noise, calls of 4 chunks: each worker forms its chunks' parts in one program (GradientParts.many),
    as GPU workers do; the parameters are the ones the driver's parts give."""
    config = dataclasses.replace(CONFIG, perturbation_rank=1)
    on_workers, rows = _train(tmp_path / "workers", compile_cache_dir, config=config, workers=1, chunks_per_call=4,
                              gradient_on="workers")
    assert all(row["gradient_parts_on_driver"] == 0 for row in rows)  # every part came from the worker
    on_driver, _ = _train(tmp_path / "driver", compile_cache_dir, config=config, workers=1, gradient_on="driver")
    assert on_workers["parameter_hash"] == on_driver["parameter_hash"]


def test_launches_of_two_chunks_give_the_same_parameters_on_any_workers_and_through_a_kill(
        tmp_path, compile_cache_dir):
    """--chunks-per-launch 2: the pool hands a worker whole launches; a kill hands a launch's chunks on, and the
    worker that takes them runs the same launch: one worker or two, killed or not, the same parameters."""
    config = dataclasses.replace(CONFIG, chunks_per_launch=2)
    alone, _ = _train(tmp_path / "one", compile_cache_dir, config=config, workers=1)
    killed, rows = _train(tmp_path / "two", compile_cache_dir, config=config, kill_schedule=frozenset({(1, 2)}))
    assert killed["workers_killed"] == 1 and sum(row["requeued_chunks"] for row in rows) >= 2
    assert killed["parameter_hash"] == alone["parameter_hash"]


def test_sigkilled_workers_mid_iteration(tmp_path, compile_cache_dir, reference_hash):
    # Right after chunk 0 of iteration 1 and chunk 3 of iteration 2 are handed out,
    # the process holding them is SIGKILLed.
    result, rows = _train(tmp_path, compile_cache_dir, kill_schedule=frozenset({(1, 0), (2, 3)}))
    assert result["workers_killed"] == 2 and sum(row["workers_lost"] for row in rows) == 2
    assert (result["workers_lost"], result["workers_killed_hung"]) == (2, 0)  # killed by chaos, found dead
    assert sum(row["requeued_chunks"] for row in rows) >= 2
    assert result["parameter_hash"] == reference_hash


def test_node_removed_and_another_added(tmp_path, compile_cache_dir, reference_hash, ray_cluster):
    first = ray_cluster.add_node(num_cpus=2, resources={"elastic": 2}, object_store_memory=OBJECT_STORE_BYTES)
    ray_cluster.wait_for_nodes()
    replacement = {}

    def swap_nodes(row):
        if row["iteration"] == 2:
            ray_cluster.remove_node(first)
            replacement["node"] = ray_cluster.add_node(
                num_cpus=2, resources={"elastic": 2}, object_store_memory=OBJECT_STORE_BYTES)
            ray_cluster.wait_for_nodes()

    try:
        result, rows = _train(tmp_path, compile_cache_dir, on_iteration=swap_nodes,
                              worker_resources=(("elastic", 1.0),))
    finally:
        for node in [replacement.get("node")]:
            if node is not None:
                ray_cluster.remove_node(node)
    assert result["parameter_hash"] == reference_hash
    assert [row["worker_nodes"] for row in rows[:2]] == [[first.node_id[:12]]] * 2
    new_node = replacement["node"].node_id[:12]
    assert [row["worker_nodes"] for row in rows[2:]] == [[new_node]] * 2  # the new node's actors got the work
    assert "new_worker_first_result_s" in rows[2]


def test_min_fraction_ends_an_iteration_without_its_hung_chunk(tmp_path, monkeypatch, ray_session, compile_cache_dir):
    """Chunk 1 of the first iteration never finishes. With half the chunks enough, the iteration ends without
    it: no kill, no requeue, fewer pairs. (Were min_fraction ignored, the chunk would hang past its deadline on
    each worker in turn until the run gave up on it.)"""
    from pizero_ray import es

    _fake_workers(monkeypatch, hang_on=(es.iteration_seed(CONFIG.seed, 0), CONFIG.chunk_size))
    result, rows = _train(tmp_path, compile_cache_dir, workers=1, min_fraction=0.5, chunk_timeout_s=3.0)
    assert result["iteration"] == ITERATIONS and result["workers_killed"] == 0
    first = rows[0]
    assert CONFIG.population // 2 <= first["pairs_evaluated"] < CONFIG.population
    assert first["requeued_chunks"] == 0


@pytest.mark.parametrize("rank, gradient_on, kept", [(1, "auto", False), (0, "auto", True), (1, "workers", True),
                                                     (0, "driver", False)])
def test_workers_keep_their_noise_only_where_parts_are_asked_of_them(monkeypatch, rank, gradient_on, kept):
    import types

    from pizero_ray.trainer import workers
    from pizero_ray.trainer.options import PoolOptions
    from pizero_ray.trainer.pool import WorkerPool

    started = []

    def start_worker(*args, keep_noise, **kwargs):  # records what the pool asks for; starts nothing
        started.append(keep_noise)
        return types.SimpleNamespace(ready=types.SimpleNamespace(remote=lambda: None))

    monkeypatch.setattr(workers, "start_worker", start_worker)
    WorkerPool(build_config("tiny", perturbation_rank=rank), PoolOptions(workers=2, gradient_on=gradient_on))
    assert started == [kept, kept]


def test_chaos_command_reports_identical_hashes(tmp_path, compile_cache_dir, capsys):
    import json

    from pizero_ray.cli import main

    # One worker and one kill: it takes the pool's only worker, whose chunks then wait for its replacement
    # (several kills, with a second worker carrying on, are test_sigkilled_workers_mid_iteration's).
    code = main(["chaos", "--run-dir", str(tmp_path), "--preset", "tiny", "--population", "8", "--planner", "none",
                 "--iterations", "2", "--kills", "1", "--workers", "1", "--compile-cache", compile_cache_dir,
                 "--no-progress"])
    report = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert code == 0 and report["identical"] and report["workers_killed"] == 1
    assert report["clean_parameter_hash"] == report["chaos_parameter_hash"]


def test_gradient_parts_of_a_dead_worker_are_computed_by_the_driver(ray_session, compile_cache_dir):
    import functools

    import numpy as np

    from pizero_ray import envs, es
    from pizero_ray.es import population
    from pizero_ray.trainer.options import PoolOptions
    from pizero_ray.trainer.pool import WorkerPool

    theta, layout = population.flat_params(CONFIG, envs.make(CONFIG.env))
    strategy = es.make_strategy(CONFIG, layout.perturbation)
    seed = strategy.ask(strategy.init(theta))
    pool = WorkerPool(CONFIG, PoolOptions(workers=1, compile_cache=compile_cache_dir))
    try:
        theta_ref = ray_session.put(np.asarray(theta))
        result = pool.score_population(theta_ref, seed)
        weights = strategy.weights(result.scores, result.valid)
        compute_here = functools.partial(strategy.parts.chunk_here, seed, weights)
        from_worker, computed_here = pool.gradient_parts(seed, weights, result.owners, compute_here)
        assert computed_here == 0  # the worker kept every chunk's noise

        result = pool.score_population(theta_ref, seed)  # again, then the worker dies before the parts are asked for
        (worker,) = {id(owner): owner for owner in result.owners.values()}.values()  # the pool's one worker
        ray_session.kill(worker.actor, no_restart=True)
        _wait_until_dead(ray_session, worker.actor)  # kill is asynchronous: a queued call could still be served
        from_driver, computed_here = pool.gradient_parts(seed, weights, result.owners, compute_here)
        assert computed_here == CONFIG.num_chunks
        for a, b in zip(from_worker, from_driver):
            np.testing.assert_array_equal(a, b)
    finally:
        pool.shutdown()


def test_gpu_workers_regenerate_a_dead_workers_parts(ray_session, ray_cluster, compile_cache_dir):
    """With GPU workers a lost chunk's part comes from a surviving worker, not the driver.

    A CPU draws some normals a few ulps away from a GPU's (measured on an H200),
    so only the workers' backend regenerates the bits the dead worker kept.
    The node's GPU is a Ray resource only: the workers compute on its CPUs.
    """
    import functools
    import time

    import numpy as np

    from pizero_ray import envs, es
    from pizero_ray.es import population
    from pizero_ray.trainer.options import PoolOptions
    from pizero_ray.trainer.pool import WorkerPool

    node = ray_cluster.add_node(num_cpus=2, num_gpus=1, resources={"fake_gpu_node": 2},
                                object_store_memory=OBJECT_STORE_BYTES)
    ray_cluster.wait_for_nodes()
    theta, layout = population.flat_params(CONFIG, envs.make(CONFIG.env))
    strategy = es.make_strategy(CONFIG, layout.perturbation)
    seed = strategy.ask(strategy.init(theta))
    pool = WorkerPool(CONFIG, PoolOptions(workers=2, gpus_per_worker=0.5, compile_cache=compile_cache_dir,
                                          worker_resources=(("fake_gpu_node", 1.0),)))
    try:
        theta_ref = ray_session.put(np.asarray(theta))
        deadline = time.time() + 300
        while time.time() < deadline:  # until both workers are up and each evaluated a chunk
            result = pool.score_population(theta_ref, seed)
            if len({id(owner) for owner in result.owners.values()}) == 2:
                break
            time.sleep(1)
        weights = strategy.weights(result.scores, result.valid)
        compute_here = functools.partial(strategy.parts.chunk_here, seed, weights)
        dead = result.owners[0]
        ray_session.kill(dead.actor, no_restart=True)
        _wait_until_dead(ray_session, dead.actor)
        parts, computed_here = pool.gradient_parts(seed, weights, result.owners, compute_here)
        assert len({id(owner) for owner in result.owners.values()}) == 2
        assert computed_here == 0  # the survivor regenerated the dead worker's chunks
        for index, part in enumerate(parts):
            np.testing.assert_array_equal(part, compute_here(index))
    finally:
        pool.shutdown()
        ray_cluster.remove_node(node)


def _wait_until_dead(ray, actor, timeout_s: float = 30.0) -> None:
    import time

    from ray.exceptions import GetTimeoutError, RayActorError

    deadline = time.time() + timeout_s
    while time.time() < deadline:
        try:
            ray.get(actor.ready.remote(), timeout=5)
        except RayActorError:
            return
        except GetTimeoutError:
            pass
        time.sleep(0.05)
    raise AssertionError(f"the killed actor still answers after {timeout_s} s")


def _fake_workers(monkeypatch, **behaviour):
    fake_workers.use(monkeypatch, CONFIG, **behaviour)


def _ready_pool(ray, options, population_seed=1):
    """A pool whose every worker is up (each has answered ``ready``)."""
    import time

    import numpy as np

    from pizero_ray.trainer.pool import WorkerPool

    pool = WorkerPool(CONFIG, options)
    theta_ref = ray.put(np.zeros(3, np.float32))
    deadline = time.time() + 120
    while pool.live_workers < options.workers and time.time() < deadline:
        pool.score_population(theta_ref, population_seed)
    assert pool.live_workers == options.workers
    return pool, theta_ref


def test_idle_workers_lost_with_their_node_never_take_a_chunk(ray_session, monkeypatch):
    """Nine of ten idle workers die at once, as a node's would. The first chunk to find one dead puts its
    node's other workers under suspicion: each must answer a ping before it gets a chunk, so no chunk is
    handed from dead worker to dead worker until it counts as a bug (MAX_CHUNK_FAILURES) and the run stops."""
    from pizero_ray.trainer.options import PoolOptions

    _fake_workers(monkeypatch)
    pool, theta_ref = _ready_pool(ray_session, PoolOptions(workers=10, compile_cache=None))
    try:
        *dead, alive = pool._workers
        for worker in dead:
            ray_session.kill(worker.actor, no_restart=True)
        for worker in dead:
            _wait_until_dead(ray_session, worker.actor)
        pool._options = dataclasses.replace(pool._options, workers=1)  # no replacements: the survivor does it all
        result = pool.score_population(theta_ref, 2)
        assert result.valid.all() and pool._workers == [alive] and pool.workers_lost == 9
        # Chunks found dead workers only until each node's first death (the test cluster has two nodes), and
        # took the chunks in flight there back with them: pings found the rest.
        assert result.requeued_chunks <= 2 * CONFIG.num_chunks < 9
    finally:
        pool.shutdown()


def _one_chunk_in_flight(ray, pool, theta_ref, deadline):
    """A queue whose chunk 0 is in flight on the pool's one worker, its result already in (a put object)."""
    import numpy as np

    from pizero_ray.trainer.pool import Traffic, _ChunkQueue

    (worker,) = pool._workers
    queue = _ChunkQueue(pool, theta_ref, 1, 0, Traffic())
    ref = ray.put(np.zeros((CONFIG.chunk_size, 2), np.float32))
    ray.wait([ref])
    queue.in_flight[ref] = ((0,), worker, deadline)
    worker.in_flight += 1
    return queue, worker, ref


def test_a_chunk_whose_result_is_in_at_its_deadline_is_collected_not_killed(ray_session, monkeypatch):
    import time

    from pizero_ray.trainer.options import PoolOptions

    _fake_workers(monkeypatch)
    pool, theta_ref = _ready_pool(ray_session, PoolOptions(workers=1, compile_cache=None))
    try:
        queue, worker, ref = _one_chunk_in_flight(ray_session, pool, theta_ref, deadline=time.time() - 1)
        queue.expire(time.time())  # past the deadline, but the result is in: not a hang
        assert pool._workers == [worker] and ref in queue.in_flight
        queue.collect(ref)
        assert 0 in queue.results and pool.workers_lost == 0
    finally:
        pool.shutdown()


def test_a_worker_dropped_when_its_result_cannot_be_fetched_is_killed(ray_session, monkeypatch):
    """Dropped alive (a fetch that timed out), it would hold its CPUs and GPUs for nothing."""
    import time

    from ray.exceptions import GetTimeoutError

    from pizero_ray.trainer.options import PoolOptions

    _fake_workers(monkeypatch)
    pool, theta_ref = _ready_pool(ray_session, PoolOptions(workers=1, compile_cache=None))
    try:
        queue, worker, ref = _one_chunk_in_flight(ray_session, pool, theta_ref, deadline=time.time() + 60)
        real_get = ray_session.get

        def get(refs, *args, **kwargs):
            if refs == ref:
                raise GetTimeoutError("the fetch timed out")
            return real_get(refs, *args, **kwargs)

        monkeypatch.setattr(ray_session, "get", get)
        queue.collect(ref)
        monkeypatch.setattr(ray_session, "get", real_get)
        assert pool._workers == [] and list(queue.pending) == [0] + list(range(CONFIG.num_chunks))
        _wait_until_dead(ray_session, worker.actor)
    finally:
        pool.shutdown()


def _never(index):
    raise AssertionError(f"chunk {index}'s part computed here")


def test_a_stop_interrupts_the_wait_for_slow_gradient_parts(ray_session, monkeypatch):
    import time

    import numpy as np

    from pizero_ray.trainer.options import PoolOptions
    from pizero_ray.trainer.pool import Interrupted, WorkerPool

    _fake_workers(monkeypatch, part_delay_s=3600)
    pool = WorkerPool(CONFIG, PoolOptions(workers=1, compile_cache=None))  # the chunk timeout is 300 s
    try:
        result = pool.score_population(ray_session.put(np.zeros(3, np.float32)), 1)
        stop_at = time.time() + 0.3
        with pytest.raises(Interrupted):
            pool.gradient_parts(1, np.ones(CONFIG.population, np.float32), result.owners, _never,
                                should_stop=lambda: time.time() > stop_at)
        assert time.time() - stop_at < 1.5  # looked at every POLL_S (0.5 s)
    finally:
        pool.shutdown()


def test_sigterm_while_waiting_for_gradient_parts_saves_the_last_finished_iteration(
        tmp_path, monkeypatch, ray_session, compile_cache_dir):
    import time

    from pizero_ray import es

    _fake_workers(monkeypatch, sigterm_on_seed=es.iteration_seed(CONFIG.seed, 1))  # in the second iteration
    started = time.time()
    result, rows = _train(tmp_path, compile_cache_dir, workers=1)  # the chunk timeout is 300 s
    assert time.time() - started < 120
    assert result["stopped_by"] == "SIGTERM" and result["iteration"] == 1
    assert [row["iteration"] for row in rows] == [1]
    assert methods.load_run(tmp_path).iteration == 1  # the checkpoint saved on the way out


def test_a_straggler_hung_past_the_chunk_timeout_is_killed_and_replaced(ray_session, monkeypatch):
    import time

    import numpy as np

    from pizero_ray.trainer.options import PoolOptions
    from pizero_ray.trainer.pool import WorkerPool

    _fake_workers(monkeypatch, hang_on=(1, 2))  # chunk 1 of the iteration with seed 1
    timeout_s = 1.5
    pool = WorkerPool(CONFIG, PoolOptions(workers=1, compile_cache=None, chunk_timeout_s=timeout_s,
                                           min_fraction=0.5))
    try:
        theta_ref = ray_session.put(np.zeros(3, np.float32))
        first = pool.score_population(theta_ref, 1)
        assert not first.valid[2:4].any()  # chunk 1 is left running, a straggler
        (hung,) = pool._workers
        time.sleep(2 * timeout_s + 0.5)  # past its deadline (it was handed out behind chunk 0: two timeouts)
        second = pool.score_population(theta_ref, 2)
        assert hung not in pool._workers and len(pool._workers) == 1  # killed, and a new worker in its slot
        assert (pool.workers_killed_hung, pool.workers_lost) == (1, 0)
        assert second.valid.sum() >= CONFIG.population // 2
        _wait_until_dead(ray_session, hung.actor)
    finally:
        pool.shutdown()


def test_workers_that_die_starting_stop_the_run_with_the_error_in_one_line(tmp_path, ray_session, monkeypatch):
    from pizero_ray.trainer import workers

    class BrokenWorker:  # pickled by value: its __init__ fails as a worker with a bad environment would
        def __init__(self):
            raise ValueError("the environment's step returned a reward of shape (3,)")

        def ready(self):
            return {}

    def start_worker(*args, **kwargs):
        import ray
        return ray.remote(BrokenWorker).options(num_cpus=0).remote()

    monkeypatch.setattr(workers, "start_worker", start_worker)
    with pytest.raises(driver.TrainingError) as raised:
        _train(tmp_path, "none", workers=1)
    message = str(raised.value)
    assert "\n" not in message
    assert message == ("environment tsp, method pizero: workers keep dying while starting: "
                       "ValueError: the environment's step returned a reward of shape (3,)")


def test_chunks_per_call_must_be_a_whole_number_of_launches():
    """A call of 3 chunks with launches of 2 would split a launch across two calls, run on two workers."""
    from pizero_ray.config import ConfigError
    from pizero_ray.trainer.options import PoolOptions
    from pizero_ray.trainer.pool import WorkerPool

    launches_of_two = dataclasses.replace(CONFIG, chunks_per_launch=2)
    with pytest.raises(ConfigError) as raised:
        PoolOptions(chunks_per_call=3).check_against(launches_of_two)
    assert str(raised.value) == "--chunks-per-call 3 is not a multiple of --chunks-per-launch 2"
    PoolOptions(chunks_per_call=4).check_against(launches_of_two)
    PoolOptions().check_against(launches_of_two)  # 1, the default: a launch per call
    PoolOptions(chunks_per_call=3).check_against(CONFIG)
    with pytest.raises(ConfigError):  # before any worker is asked for
        WorkerPool(launches_of_two, PoolOptions(chunks_per_call=3))


# ------------------------------------------------------------------ a cluster that shrinks, and what the pool counts

# --worker-wait-minutes for these tests: 5 seconds without a live worker (a replacement fake worker took 1.1 s to
# start on a busy 2-core machine), and 1 second where none is meant to start.
WAIT_MINUTES = 5 / 60
SHORT_WAIT_MINUTES = 1 / 60


def _fake_run(path, monkeypatch, compile_cache_dir, **behaviour_and_options):
    """A run on fake workers, the driver forming every gradient part from the fakes' scores: its parameters say
    whether every chunk's scores arrived, once, whatever happened to the workers."""
    behaviours = {"hang_once_on", "start_delay_s", "started_dir", "part_delay_s"}
    fake_workers.use(monkeypatch, CONFIG, **{k: v for k, v in behaviour_and_options.items() if k in behaviours})
    options = {k: v for k, v in behaviour_and_options.items() if k not in behaviours}
    return _train(path, compile_cache_dir, gradient_on="driver", **options)


def _warnings(caplog, text):
    return [record.getMessage() for record in caplog.records if text in record.getMessage()]


def test_a_run_that_loses_every_worker_late_waits_for_new_ones_and_ends_as_undisturbed(
        tmp_path, ray_session, monkeypatch, compile_cache_dir, caplog):
    """Both workers are killed in the third iteration, after the run has trained for longer than the worker wait,
    and their replacements take a while to start. The wait counts from the loss, not from the last worker to
    become ready: the run waits for them, says so once, and ends with the parameters of a run that lost
    nothing."""
    import os
    import time

    clean, _ = _fake_run(tmp_path / "clean", monkeypatch, compile_cache_dir)
    started = tmp_path / "started"
    started.mkdir()

    def both_workers_up(info):  # so that both are ready from the first iteration on, and both are killed
        deadline = time.time() + 60
        while len(os.listdir(started)) < 2 and time.time() < deadline:
            time.sleep(0.05)

    def outlast_the_wait(row):
        if row["iteration"] == 2:
            time.sleep(60 * WAIT_MINUTES + 0.5)

    result, rows = _fake_run(tmp_path / "chaos", monkeypatch, compile_cache_dir, on_start=both_workers_up,
                             on_iteration=outlast_the_wait, started_dir=str(started),
                             worker_wait_minutes=WAIT_MINUTES, kill_schedule=frozenset({(2, 0), (2, 1)}))
    assert result["workers_killed"] == 2 and rows[2]["workers_lost"] == 2 and rows[2]["requeued_chunks"] >= 2
    assert result["parameter_hash"] == clean["parameter_hash"]
    (waiting,) = _warnings(caplog, "no live worker since")
    assert "\n" not in waiting and "waiting up to 0.0833333 min for the cluster to supply one" in waiting


def test_a_pool_that_lost_its_last_worker_waits_the_worker_wait_from_the_loss_then_says_so(
        ray_session, monkeypatch):
    """The pool's one worker has been ready for longer than the wait when it dies, and no replacement can
    start (it asks for a resource no node has): the pool waits the whole wait from the loss, then stops with
    one line saying how long it has had no live worker and what the cluster has."""
    import time

    from pizero_ray.trainer.options import PoolOptions
    from pizero_ray.trainer.pool import TrainingError

    _fake_workers(monkeypatch)
    options = PoolOptions(workers=1, compile_cache=None, worker_wait_minutes=SHORT_WAIT_MINUTES)
    # Started with the default wait: on a busy machine a worker can take longer than the short one to start.
    pool, theta_ref = _ready_pool(ray_session, dataclasses.replace(options, worker_wait_minutes=15.0))
    pool._options, pool._wait.wait_minutes = options, SHORT_WAIT_MINUTES
    try:
        time.sleep(60 * SHORT_WAIT_MINUTES + 0.5)
        (worker,) = pool._workers
        ray_session.kill(worker.actor, no_restart=True)
        _wait_until_dead(ray_session, worker.actor)
        pool._options = dataclasses.replace(options, worker_resources=(("no_such_node", 1.0),))
        lost = time.time()
        with pytest.raises(TrainingError) as raised:
            pool.score_population(theta_ref, 2)
        assert time.time() - lost >= 60 * SHORT_WAIT_MINUTES
    finally:
        pool.shutdown()
    message = str(raised.value)
    assert "\n" not in message and message.startswith("no live worker since ")
    assert "when the pool lost its last one" in message and "--worker-wait-minutes 0.0166667" in message
    assert "no_such_node 0" in message  # what the cluster has of what a worker asks for


def test_a_node_lost_while_its_workers_start_does_not_stop_the_run(
        tmp_path, ray_cluster, ray_session, monkeypatch, compile_cache_dir):
    """Three of four workers start on a node that is removed before they are ready. They die together, of one
    cause, with one node: one death at start-up, not three in a row, and the run goes on with the fourth."""
    import os
    import time

    clean, _ = _fake_run(tmp_path / "clean", monkeypatch, compile_cache_dir)
    doomed = ray_cluster.add_node(num_cpus=0, resources={"starting": 3}, object_store_memory=OBJECT_STORE_BYTES)
    kept = ray_cluster.add_node(num_cpus=0, resources={"starting": 1}, object_store_memory=OBJECT_STORE_BYTES)
    ray_cluster.wait_for_nodes()
    started = tmp_path / "started"
    started.mkdir()

    def remove_the_node_as_its_workers_start(info):
        deadline = time.time() + 60
        while len(os.listdir(started)) < 4 and time.time() < deadline:
            time.sleep(0.05)
        ray_cluster.remove_node(doomed)

    try:
        result, rows = _fake_run(tmp_path / "run", monkeypatch, compile_cache_dir,
                                 on_start=remove_the_node_as_its_workers_start, workers=4,
                                 worker_resources=(("starting", 1.0),), start_delay_s=lambda number: 3.0,
                                 started_dir=str(started))
    finally:
        ray_cluster.remove_node(kept)
    assert result["parameter_hash"] == clean["parameter_hash"]
    assert [row["workers"] for row in rows] == [1] * ITERATIONS


def test_a_worker_whose_second_device_fails_to_compile_is_handed_chunks_for_one(
        ray_session, compile_cache_dir, caplog):
    """A 2-device worker compiles its first device's programs, then fails on the second's (as a GPU out of
    memory would). It reports the device that compiled, and the pool sizes its calls by that, and says why."""
    import time

    import numpy as np

    from pizero_ray import envs
    from pizero_ray.es import population
    from pizero_ray.trainer import workers
    from pizero_ray.trainer.options import PoolOptions
    from pizero_ray.trainer.pool import WorkerPool

    class SecondDeviceFailsToCompile(workers.RolloutWorker):  # defined here: Ray pickles it by value
        def __init__(self, *args, **kwargs):
            from pizero_ray.es import population
            make_pair_scorer = population.make_pair_scorer

            class FirstDeviceOnly:
                def __init__(self, scorer):
                    self._scorer = scorer

                def lower(self, theta, *rest):
                    import jax
                    if theta.sharding.device_set != {jax.local_devices()[0]}:
                        raise RuntimeError("RESOURCE_EXHAUSTED: out of memory compiling for the second device")
                    return self._scorer.lower(theta, *rest)

            population.make_pair_scorer = lambda *a, **k: FirstDeviceOnly(make_pair_scorer(*a, **k))
            super().__init__(*args, **kwargs)

    def start(config_json, num_cpus, num_gpus, cache_dir, resources, pin_cores, keep_noise):
        return ray_session.remote(SecondDeviceFailsToCompile).options(num_cpus=0, max_concurrency=3).remote(
            config_json, cache_dir, 2, False, cpu_only=True, keep_noise=keep_noise)

    theta = population.flat_params(CONFIG, envs.make(CONFIG.env))[0]
    pool = WorkerPool(CONFIG, PoolOptions(workers=1, cpus_per_worker=2, compile_cache=compile_cache_dir),
                      workers.WorkerFactory(start, workers.stop_worker))
    try:
        theta_ref = ray_session.put(np.asarray(theta))
        deadline = time.time() + 300
        while time.time() < deadline:  # until the worker is ready and every compile it tried is over
            result = pool.score_population(theta_ref, 1)
            (worker,) = pool._workers
            if worker.ready and not worker.info.get("compiling"):
                break
        assert result.valid.all()
        assert worker.info["devices"] == 1
    finally:
        pool.shutdown()
    (said,) = _warnings(caplog, "RESOURCE_EXHAUSTED")
    assert "\n" not in said and "1 of its 2 devices" in said


def test_a_worker_that_misses_the_gradient_part_deadline_is_killed_as_hung(ray_session, monkeypatch):
    import numpy as np

    from pizero_ray.trainer.options import PoolOptions
    from pizero_ray.trainer.pool import WorkerPool

    _fake_workers(monkeypatch, part_delay_s=3600)
    pool = WorkerPool(CONFIG, PoolOptions(workers=1, compile_cache=None, chunk_timeout_s=1.0, gradient_on="workers"))
    try:
        result = pool.score_population(ray_session.put(np.zeros(3, np.float32)), 1)
        (worker,) = pool._workers
        parts, computed_here = pool.gradient_parts(1, np.ones(CONFIG.population, np.float32), result.owners,
                                                   lambda index: np.zeros(3, np.float32))
        assert computed_here == CONFIG.num_chunks
        assert worker not in pool._workers and (pool.workers_killed_hung, pool.workers_lost) == (1, 0)
        _wait_until_dead(ray_session, worker.actor)
    finally:
        pool.shutdown()


def test_a_worker_hung_on_a_chunk_counts_as_killed_hung_not_as_lost(
        tmp_path, ray_session, monkeypatch, compile_cache_dir):
    """The first worker handed chunk 1 of the second iteration hangs on it: the pool kills it at the chunk's
    deadline, and the rows and the result count it as hung, not as lost (died) or killed by chaos."""
    from pizero_ray import es

    clean, _ = _fake_run(tmp_path / "clean", monkeypatch, compile_cache_dir)
    result, rows = _fake_run(tmp_path / "hung", monkeypatch, compile_cache_dir, chunk_timeout_s=2.0,
                             hang_once_on=(es.iteration_seed(CONFIG.seed, 1), CONFIG.chunk_size))
    assert [row["workers_killed_hung"] for row in rows] == [0, 1, 0, 0]
    assert [row["workers_lost"] for row in rows] == [0] * ITERATIONS
    assert (result["workers_killed"], result["workers_lost"], result["workers_killed_hung"]) == (0, 0, 1)
    assert result["parameter_hash"] == clean["parameter_hash"]


def test_a_pool_asked_for_more_workers_than_the_cluster_holds_says_so_once(ray_session, monkeypatch, caplog):
    import numpy as np

    from pizero_ray.trainer.options import PoolOptions
    from pizero_ray.trainer.pool import WorkerPool

    _fake_workers(monkeypatch)  # the fakes ask for no CPU: they all start, but real ones of 2 CPUs could not
    cpus = ray_session.cluster_resources()["CPU"]
    pool = WorkerPool(CONFIG, PoolOptions(workers=4, cpus_per_worker=2, compile_cache=None))
    try:
        theta_ref = ray_session.put(np.zeros(3, np.float32))
        pool.score_population(theta_ref, 1)
        pool.score_population(theta_ref, 2)
    finally:
        pool.shutdown()
    (said,) = _warnings(caplog, "asked for 4 workers")
    assert said == (f"pizero: warning: asked for 4 workers of 2 CPU each; the cluster has {cpus:g} CPU in all: "
                    f"at most {int(cpus // 2)} can run at once")


def test_start_up_deaths_count_a_lost_node_once_and_each_cause_apart():
    from pizero_ray.trainer.pool import _StartupDeaths

    def node_died(node):  # the text Ray 2.60 gives an actor whose node died while it started
        return RuntimeError(f"The actor died unexpectedly before finishing this task.\n\tclass_name: RolloutWorker\n"
                            f"The actor died because its node has died. Node Id: {node}\n\tthe actor's node was "
                            "terminated expectedly: received SIGTERM\nThe actor never ran - it was cancelled before "
                            "it started running.")

    deaths = _StartupDeaths()
    assert [deaths.record(node_died("aa01")) for _ in range(4)] == [None] * 4  # one node's four workers: one
    assert deaths.record(ValueError("a bad reward")) is None  # another cause: not added to the node's
    assert deaths.record(node_died("bb02")) is None
    assert deaths.record(node_died("cc03")) == ("workers keep dying while starting: their node died "
                                                "(3 nodes, with no worker ready in between)")
    deaths.clear()  # a worker became ready
    assert [deaths.record(ValueError("a bad reward")) for _ in range(3)][-1] == (
        "workers keep dying while starting: a bad reward")


def test_what_a_worker_raised_is_one_line_naming_the_exception_not_its_traceback():
    from ray.exceptions import RayTaskError

    from pizero_ray.trainer.pool import last_line, task_failure

    traceback = ("Traceback (most recent call last):\n  File \"workers.py\", line 60, in score_chunk\n"
                 "jaxlib.XlaRuntimeError: INTERNAL: CpuCallback error: RuntimeError: step broke at t=7\n\nAt:\n"
                 "  mine.py(12): step\n")
    cause = RuntimeError("INTERNAL: CpuCallback error: RuntimeError: step broke at t=7\n\nAt:\n  mine.py(12): step")
    assert task_failure(RayTaskError("score_chunk", traceback, cause)) == (
        "RuntimeError: INTERNAL: CpuCallback error: RuntimeError: step broke at t=7")
    died = ("The actor died because of an error raised in its creation task\n  File \"envs.py\", line 3\n"
            "NotImplementedError: vmap is only supported for the pure_callback primitive\n"
            "--------------------\nFor simplicity, JAX has removed its internal frames from the traceback of the "
            "following exception. Set JAX_TRACEBACK_FILTERING=off to include these.")
    assert last_line(died) == "NotImplementedError: vmap is only supported for the pure_callback primitive"
