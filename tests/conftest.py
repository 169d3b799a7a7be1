import functools
import os
import pickle
import shutil
import tempfile
import threading
import time
import uuid

os.environ.setdefault("JAX_PLATFORMS", "cpu")
os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
# Compiling the tiny test programs is most of this suite's time. On CPU, XLA's
# backend optimisation level 0 and its older (non-MLIR) fusion emitters cut
# the compile of the tiny TSP rollout from 11-15 s to 2-3 s on this 2-core
# machine (same scores); the programs run a little slower, but they are tiny.
# Set here, before JAX starts, so that the Ray workers and `pizero`
# subprocesses the tests start compile the same way. A flag already in
# XLA_FLAGS wins; GPU runs (JAX_PLATFORMS=cuda,cpu) keep XLA's defaults.
FAST_COMPILE_FLAGS = {"xla_backend_optimization_level": "0", "xla_cpu_use_fusion_emitters": "false"}
if os.environ["JAX_PLATFORMS"] == "cpu":
    _flags = os.environ.get("XLA_FLAGS", "")
    _flags += "".join(f" --{name}={value}" for name, value in FAST_COMPILE_FLAGS.items() if name not in _flags)
    os.environ["XLA_FLAGS"] = _flags.strip()
# One JAX compile cache for the test run, made here (never ~/.cache from an
# earlier run): `pizero` subprocesses without --compile-cache use it too, and
# reuse each other's programs as the workers do. Under pytest-xdist the workers
# share it, named by the run's id (which pytest_configure gives the controller,
# and whose cache pytest_unconfigure removes there once every worker is done):
# a program that one worker's tests compiled, the other's load.
_XDIST_RUN = os.environ.get("PYTEST_XDIST_TESTRUNUID")


def _shared_compile_cache(run_id: str) -> str:
    return os.path.join(tempfile.gettempdir(), f"pizero-test-jax-cache-{run_id}")


if _XDIST_RUN:
    SESSION_COMPILE_CACHE = _shared_compile_cache(_XDIST_RUN)
    os.makedirs(SESSION_COMPILE_CACHE, exist_ok=True)
else:
    SESSION_COMPILE_CACHE = tempfile.mkdtemp(prefix="pizero-test-jax-cache-")
os.environ["PIZERO_COMPILE_CACHE"] = SESSION_COMPILE_CACHE
# Ray's monitoring, every 5 s on every node (each agent's psutil sweep over the
# node's processes, each process's metrics export), costs a 2-core machine CPU
# that the tests need, and no test reads it. Set before any Ray process starts,
# so the test clusters, `pizero` subprocesses and the README walkthrough's
# nodes inherit it.
os.environ.setdefault("REPORTER_UPDATE_INTERVAL_MS", "60000")
os.environ.setdefault("RAY_enable_metrics_collection", "0")

import jax  # noqa: E402
import pytest  # noqa: E402

from pizero_ray.config import build_config  # noqa: E402
from pizero_ray.trainer import compile_cache  # noqa: E402

# Two CPU devices, as a 2-core worker has: single-device code runs on the
# first, and tests of chunk_scoring can deal chunks over both.
jax.config.update("jax_num_cpu_devices", 2)
# The test process uses the session's compile cache from the start, as the
# workers do (and as it did anyway once a test had trained): a program that
# another test, a worker or a subprocess compiled is loaded, not compiled again.
compile_cache.enable(SESSION_COMPILE_CACHE)

OBJECT_STORE_BYTES = 80 * 1024 * 1024


@pytest.fixture(scope="session")
def tiny_config():
    return build_config("tiny")


@pytest.fixture(scope="session")
def tsp_env():
    from pizero_ray import envs

    return envs.make("tsp")


@pytest.fixture(scope="session")
def compile_cache_dir():
    """One persistent JAX cache for the session: workers after the first skip the compile."""
    return SESSION_COMPILE_CACHE


@pytest.fixture(scope="session")
def ray_cluster():
    """One Ray instance per test session, as a multi-node cluster on this machine.

    The head holds no CPUs (only the driver runs there); one worker node holds
    3 CPUs for ordinary tests; tests that need nodes to come and go add their
    own nodes with a custom resource so that only their workers land there.
    No dashboard, as pizero's own local instance (ray_setup.init): no test
    needs it, and its processes cost a 2-core machine CPU all session long.
    """
    import ray
    from ray.cluster_utils import Cluster

    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 0, "object_store_memory": OBJECT_STORE_BYTES,
                                                            "include_dashboard": False})
    cluster.add_node(num_cpus=3, object_store_memory=OBJECT_STORE_BYTES)
    ray.init(address=cluster.address, logging_level="ERROR")
    yield cluster
    ray.shutdown()
    cluster.shutdown()


@pytest.fixture(scope="session")
def ray_session(ray_cluster):
    import ray

    return ray


def pytest_configure(config):
    config.addinivalue_line("markers", "readme_walkthrough: the README walkthrough's test (see readme_walkthrough)")
    if getattr(config.option, "numprocesses", None) and not _XDIST_RUN:  # the xdist controller: name the run
        config.option.testrunuid = config.option.testrunuid or uuid.uuid4().hex


def pytest_unconfigure(config):
    """Removes the run's compile cache: in the only process, or in the xdist controller once its workers end."""
    if os.environ.get("PYTEST_XDIST_WORKER"):
        return
    shutil.rmtree(SESSION_COMPILE_CACHE, ignore_errors=True)
    if getattr(config.option, "testrunuid", None):
        shutil.rmtree(_shared_compile_cache(config.option.testrunuid), ignore_errors=True)


@pytest.fixture(scope="session", autouse=True)
def readme_walkthrough(request, tmp_path_factory):
    """The README's cluster walkthrough (tests/test_job_submit.py), running in a background thread.

    It starts as the session begins, when its test (marked readme_walkthrough)
    is selected: the walkthrough takes minutes, mostly waiting on Ray's CLI,
    its jobs' start-ups and its nodes' shutdown, and so overlaps the other
    tests. Something with ``result()``, which waits for run_walkthrough's
    result; None when not selected. The session waits for the walkthrough
    before it ends, so its cluster is always stopped.
    """
    selected = [item for item in request.session.items if item.get_closest_marker("readme_walkthrough")]
    if not selected:
        yield None
        return
    run = functools.partial(selected[0].module.run_walkthrough, tmp_path_factory.mktemp("readme-walkthrough"))
    # Under pytest-xdist every worker collects every test but runs only its share, and which worker runs the
    # walkthrough's test is known only then: the first worker to claim it runs it from the start, and the
    # test, on whichever worker, reads its result from the directory the run's workers share (their basetemp's
    # parent). Without xdist the session's one process claims it in its own basetemp.
    base = tmp_path_factory.getbasetemp()
    shared = _SharedRun((base.parent if os.environ.get("PYTEST_XDIST_WORKER") else base) / "readme-walkthrough", run)
    yield shared
    shared.join()


class _SharedRun:
    """``function`` run once in a background thread by the first process to claim ``directory``; ``result()``
    in any process waits for its pickled outcome there (its return value, or the exception it raised)."""

    WAIT_S = 1800

    def __init__(self, directory, function):
        directory.mkdir(exist_ok=True)
        self._outcome, self._thread = directory / "outcome.pickle", None
        try:
            os.close(os.open(directory / "claim", os.O_CREAT | os.O_EXCL))
        except FileExistsError:
            return  # another worker runs it
        self._thread = threading.Thread(target=self._run, args=(function,), name="readme-walkthrough")
        self._thread.start()

    def _run(self, function):
        try:
            outcome = (True, function())
        except BaseException as error:  # noqa: BLE001 -- handed to the test, which raises it
            outcome = (False, error)
        partial = self._outcome.with_suffix(".partial")
        partial.write_bytes(pickle.dumps(outcome))
        partial.replace(self._outcome)  # whole or absent: the reader never sees half a pickle

    def result(self):
        deadline = time.monotonic() + self.WAIT_S
        while not self._outcome.exists():
            if time.monotonic() > deadline:
                raise TimeoutError(f"no outcome in {self._outcome} after {self.WAIT_S} s")
            time.sleep(0.5)
        ok, value = pickle.loads(self._outcome.read_bytes())
        if not ok:
            raise value
        return value

    def join(self):
        if self._thread is not None:
            self._thread.join()
