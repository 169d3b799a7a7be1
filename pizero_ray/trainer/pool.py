"""An elastic pool of worker actors and the queue of chunks of one iteration.

Workers come and go: a chunk whose worker dies (actor death, node loss,
preemption) or hangs past its deadline goes back on the queue and runs
elsewhere. A death puts the dead worker's idle node-mates under suspicion:
each answers a ping before it gets another chunk, so the workers of a lost
node are found dead by pings, not by handing them chunks one after another.
The pool keeps asking Ray for ``max_workers`` actors, so replacements and
actors on newly joined nodes start as soon as the cluster has room (which is
also the demand an autoscaler sees). Only workers that finished compiling get
chunks, and a worker with several devices gets as many calls at once as it has
devices compiled. Every wait has a timeout, and looks at the driver's stop
request at least every ``POLL_S``.

A cluster may have no live worker for a while (at start-up, or when it loses
every node at once and an autoscaler replaces them): the pool waits for one up
to ``--worker-wait-minutes``, counted from the start or from the loss of the
last live worker, and stops only then. Workers that die starting stop the run
only when one cause keeps killing them (``_StartupDeaths``).
"""

from __future__ import annotations

import logging
import math
import pickle
import re
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any, Callable

import numpy as np

from pizero_ray.config import Config
from pizero_ray.settings import lookup
from pizero_ray.trainer.options import PoolOptions

POLL_S = 0.5  # how often the driver looks up from ray.wait (signals, deadlines)
EXPIRY_CHECK_S = 0.1  # how often it looks for hung workers (deadlines are chunk timeouts: seconds or more)
MAX_CHUNK_FAILURES = 5  # a chunk that kills this many workers is a bug, not bad luck
MAX_STARTUP_DEATHS = 3  # starts one cause killed, with no worker ready in between: workers never will start
_log = logging.getLogger(__name__)


class TrainingError(RuntimeError):
    pass


class Interrupted(Exception):
    """A stop was requested (SIGTERM/SIGINT) while an iteration was under way."""


@dataclass(eq=False)  # a worker is itself: compared by identity, not by its fields
class _Worker:
    actor: Any
    created: float
    ready_ref: Any = None
    ready: bool = False
    in_flight: int = 0
    info: dict = field(default_factory=dict)
    first_result_s: float | None = None  # actor creation to its first chunk result
    ping_ref: Any = None  # a liveness check in flight (a node-mate died): no chunk until it answers
    ping_deadline: float = 0.0
    compile_ref: Any = None  # answers once the worker's other devices' compiles are over (``RolloutWorker.compiled``)


def serialized_bytes(obj) -> int:
    """The bytes of ``obj`` as Ray ships it: pickle protocol 5, arrays as out-of-band buffers (counted, not copied).

    Ray serialises task arguments, returns and ``ray.put`` objects this way and
    adds a little metadata of its own, which this leaves out (about 100 bytes
    per object: the bench agent's parameters measured 217,359 bytes through
    Ray's serialiser, 217,253 here).
    """
    buffers: list[pickle.PickleBuffer] = []
    header = pickle.dumps(obj, protocol=5, buffer_callback=buffers.append)
    return len(header) + sum(buffer.raw().nbytes for buffer in buffers)


# Lines of an error's text that say nothing of the error: JAX's note on the frames it filtered from a traceback,
# its rule, and Python's words between chained exceptions. Under a traceback they can be its last lines.
_SAYS_NOTHING = ("For simplicity, JAX has removed its internal frames", "-----",
                 "The above exception was the direct cause", "During handling of the above exception")


def last_line(error: BaseException | str) -> str:
    """The last telling line of an error's text: Ray's errors from an actor carry its whole traceback, whose
    last line is the exception itself (but for the lines that say nothing)."""
    lines = [line.strip() for line in str(error).splitlines()
             if line.strip() and not line.strip().startswith(_SAYS_NOTHING)]
    return lines[-1] if lines else type(error).__name__


def task_failure(error: BaseException) -> str:
    """One line for an exception a worker's call raised (a ``RayTaskError``): the exception's type and its
    message's first line, without the remote traceback Ray wraps around it."""
    cause = getattr(error, "cause", None)
    if not isinstance(cause, BaseException):
        return last_line(error)
    lines = [line.strip() for line in str(cause).splitlines()
             if line.strip() and not line.strip().startswith(_SAYS_NOTHING)]
    return f"{type(cause).__name__}: {lines[0]}" if lines else type(cause).__name__


def _what(config: Config) -> str:
    """The run's environment and method, as an error names them."""
    return f"environment {config.env}, method {config.method}"


def call_bytes(*args) -> int:
    """A remote call's arguments: each value serialised, each object reference as its id.

    A task carries a reference's id, not the object: the object itself moves
    once per node, and is counted there (``_ChunkQueue.dispatch``).
    """
    import ray

    return sum(len(arg.binary()) if isinstance(arg, ray.ObjectRef) else serialized_bytes(arg) for arg in args)


@dataclass
class Traffic:
    """Bytes one iteration moved between the driver and its workers, counted object by object as they go.

    Out: the parameters once per worker node that was handed a chunk (Ray
    fetches an object once per node; on the driver's own node that is a read of
    the shared-memory store), each chunk's call (seed, first pair, a reference),
    and, where parts are asked of workers, each chunk's weights. Back: each
    chunk's scores and each gradient part a worker returned. Objects are
    measured by ``serialized_bytes``. Not counted: Ray's task and control
    messages, and the results of stragglers ``min_fraction`` dropped.
    """

    to_workers: int = 0
    from_workers: int = 0

    def metrics(self) -> dict:
        return {"bytes_to_workers": self.to_workers, "bytes_from_workers": self.from_workers}


@dataclass
class IterationResult:
    scores: np.ndarray  # [population, 2]; rows of dropped chunks are zero
    valid: np.ndarray  # [population] bool: pairs whose scores are in
    requeued_chunks: int
    new_worker_first_result_s: list[float]
    worker_nodes: list[str]  # Ray node ids of the workers that returned chunks
    owners: dict = field(default_factory=dict)  # chunk index -> the worker that evaluated it (it kept the noise)
    # The iteration's bytes each way; the pool's gradient_parts adds its round trip to this same object.
    traffic: Traffic = field(default_factory=Traffic)


_NODE_DIED = re.compile(r"node has died\. Node Id: ([0-9a-fA-F]+)")


def _dead_node(error: BaseException) -> str | None:
    """The node whose death killed an actor, as Ray's error names it; None where the actor died otherwise."""
    found = _NODE_DIED.search(str(error))
    return found.group(1) if found else None


def _clock(seconds: float) -> str:
    return time.strftime("%H:%M:%S", time.localtime(seconds))


def _resources(amounts: dict) -> str:
    return ", ".join(f"{name} {amount:g}" for name, amount in amounts.items())


class _StartupDeaths:
    """Workers that died starting since a worker last became ready, by cause.

    A cause is the error's last line (what ``__init__`` raised, say), or the
    death of the worker's node: the workers a node held while they started
    die together, and count once for their node. One cause that has killed
    ``MAX_STARTUP_DEATHS`` starts stops the run; causes do not add up, so a
    node lost while its workers start does not stop the others starting.
    """

    NODE_DIED = "their node died"

    def __init__(self):
        self._by_cause: dict[str, set] = {}

    def clear(self) -> None:
        self._by_cause.clear()

    def record(self, error: BaseException) -> str | None:
        """Counts a worker that died starting; returns why the run should stop once its cause has killed too
        many starts, else None."""
        node = _dead_node(error)
        cause = self.NODE_DIED if node else last_line(error)
        deaths = self._by_cause.setdefault(cause, set())
        deaths.add(node or object())  # a node once, however many of its workers died; any other worker each
        if len(deaths) < MAX_STARTUP_DEATHS:
            return None
        nodes = f" ({len(deaths)} nodes, with no worker ready in between)" if node else ""
        return f"workers keep dying while starting: {cause}{nodes}"


class _LiveWorkerWait:
    """How long the pool has been without a live (ready) worker: since it started, or since it lost its last."""

    def __init__(self, wait_minutes: float):
        self.wait_minutes = wait_minutes
        self.since: float | None = time.time()  # none is live at the start
        self.after_loss = False  # the wait began when the pool lost its last live worker (else: at its start)

    def live(self) -> None:
        self.since = None

    def none_live(self, now: float) -> None:
        """The pool has no live worker: a wait begins, unless one is under way, and is announced once."""
        if self.since is None:
            self.since, self.after_loss = now, True
            _log.warning("pizero: no live worker since %s; waiting up to %g min for the cluster to supply one",
                         _clock(now), self.wait_minutes)

    def over(self, now: float) -> bool:
        return self.since is not None and now - self.since > 60.0 * self.wait_minutes

    def gave_up(self, now: float, cluster: str) -> str:
        """The one-line reason the pool stops: since when it has had no live worker, and what the cluster has."""
        when = "when the pool lost its last one" if self.after_loss else "when the pool started"
        flag = lookup(PoolOptions, "worker_wait_minutes").flag
        return (f"no live worker since {_clock(self.since)} ({now - self.since:.0f} s), {when}; gave up after "
                f"{flag} {self.wait_minutes:g}; {cluster}")


class WorkerPool:
    def __init__(self, config: Config, options: PoolOptions, factory=None):
        """``factory``: a ``workers.WorkerFactory`` (stub workers, say); None for ``RolloutWorker`` actors."""
        options.check_against(config)  # before any worker is asked for
        self._config = config
        self._options = options
        self._factory = factory
        self._config_json = config.to_json()
        self._workers: list[_Worker] = []
        self._stale: dict = {}  # refs of chunks dropped by min_fraction -> (their worker, deadline)
        self._startup_deaths = _StartupDeaths()
        self._wait = _LiveWorkerWait(options.worker_wait_minutes)
        self._cluster_checked = False  # whether the cluster's size was held against --workers (once)
        # Over the pool's life: workers SIGKILLed by a chaos run's schedule; ready workers found dead (actor
        # death, node loss, chaos kills among them); ready workers the pool killed as hung (past a deadline).
        self.chaos_kills = 0
        self.workers_lost = 0
        self.workers_killed_hung = 0
        self._kills_done: set[tuple[int, int]] = set()
        self._traffic = Traffic()  # the current iteration's bytes (score_population starts a new count)
        self.top_up()

    # ------------------------------------------------------------------ workers

    @property
    def live_workers(self) -> int:
        return sum(w.ready for w in self._workers)

    def kill_process(self, worker: _Worker) -> None:
        """SIGKILLs a worker's process, as a crash or a preemption would (same node), else kills the actor."""
        import os
        import signal

        import ray

        if worker.info.get("node_id") == ray.get_runtime_context().get_node_id():
            os.kill(worker.info["pid"], signal.SIGKILL)
        else:
            self._stop(worker.actor)
        self.chaos_kills += 1

    def top_up(self) -> None:
        """Asks Ray for actors up to ``target_workers``; they start when the cluster has room."""
        from pizero_ray.trainer import workers

        start = self._factory.start if self._factory else workers.start_worker
        while len(self._workers) < self._options.target_workers:
            actor = start(
                self._config_json, self._options.cpus_per_worker, self._options.gpus_per_worker,
                self._options.compile_cache, dict(self._options.worker_resources), self._options.pin_cores,
                keep_noise=not self._options.gradient_on_driver(self._config.perturbation_rank),
            )
            self._workers.append(_Worker(actor, time.time(), ready_ref=actor.ready.remote()))

    def _started(self, worker: _Worker, ready_ref) -> None:
        """A starting worker's ``ready`` call is done: the worker takes chunks from now on, or it died starting."""
        import ray
        from ray.exceptions import GetTimeoutError, RayError

        try:
            worker.info = ray.get(ready_ref, timeout=POLL_S)
        except GetTimeoutError:
            return
        except RayError as error:
            self._drop(worker, kill=True)  # dead already, unless only its call was lost: never leak it
            given_up = self._startup_deaths.record(error)
            if given_up:
                raise TrainingError(f"{_what(self._config)}: {given_up}") from None
            return
        worker.ready = True
        self._startup_deaths.clear()
        self._wait.live()
        if worker.info.get("compiling"):  # its other devices are still compiling: hear when they are done
            worker.compile_ref = worker.actor.compiled.remote()

    def _compiled(self, worker: _Worker) -> None:
        """A worker's other devices finished compiling, or failed to: it runs as many calls at once as compiled."""
        import ray
        from ray.exceptions import GetTimeoutError, RayError

        try:
            report = ray.get(worker.compile_ref, timeout=POLL_S)
        except GetTimeoutError:
            return
        except RayError:
            worker.compile_ref = None
            self.lose(worker)  # it died
            return
        worker.compile_ref = None
        worker.info.update(report)
        if report.get("compile_error"):
            _log.warning("pizero: warning: a worker on node %s compiled its rollout for %d of its %d devices and "
                         "runs on those (%s)", str(worker.info.get("node_id", "?"))[:12], report["devices"],
                         report["local_devices"], last_line(report["compile_error"]))

    def _expire_stale(self, now: float) -> None:
        """A worker still on a chunk dropped by min_fraction past its deadline is hung: kill it (top_up replaces it)."""
        import ray

        expired = [ref for ref, (_, deadline) in self._stale.items() if now > deadline]
        if expired:  # a result that is in but not yet collected (one per ray.wait) is no hang
            done, _ = ray.wait(expired, num_returns=len(expired), timeout=0, fetch_local=False)
            for ref in set(expired) - set(done):
                self.lose(self._stale[ref][0], hung=True)
        for ref, (worker, _) in list(self._stale.items()):
            if worker not in self._workers:  # gone (killed above, or died): nothing to wait for
                del self._stale[ref]

    def _stop(self, actor) -> None:
        from pizero_ray.trainer import workers

        (self._factory.stop if self._factory else workers.stop_worker)(actor)

    def _drop(self, worker: _Worker, kill: bool) -> None:
        if worker in self._workers:
            self._workers.remove(worker)
        if kill:
            self._stop(worker.actor)

    def lose(self, worker: _Worker, hung: bool = False) -> None:
        """A ready worker died (or ``hung``: missed a deadline): drop it (killed, so a hung or half-dead actor
        frees its resources), count it, and check its idle node-mates before they get chunks: a node lost takes
        all its workers at once. The pool's last live worker lost starts the wait for another."""
        if worker not in self._workers:
            return
        self._drop(worker, kill=True)
        if hung:
            self.workers_killed_hung += 1
        else:
            self.workers_lost += 1
        if self.live_workers == 0:
            self._wait.none_live(time.time())
        node = worker.info.get("node_id")
        deadline = time.time() + self._options.chunk_timeout_s
        for mate in self._workers:
            if mate.ready and mate.in_flight == 0 and mate.ping_ref is None and mate.info.get("node_id") == node:
                mate.ping_ref, mate.ping_deadline = mate.actor.ready.remote(), deadline

    def _pinged(self, worker: _Worker) -> None:
        """A suspect worker's ping is back: it is alive and takes chunks again, or it is dropped."""
        import ray
        from ray.exceptions import GetTimeoutError, RayError

        try:
            ray.get(worker.ping_ref, timeout=POLL_S)
        except GetTimeoutError:  # (a RayError too) its answer is in but cannot be fetched: killed as hung
            self.lose(worker, hung=True)
        except RayError:
            self.lose(worker)
        worker.ping_ref = None

    def _expire_pings(self, now: float) -> None:
        """A suspect that has not answered its ping by the chunk timeout is hung: drop it."""
        for worker in [w for w in self._workers if w.ping_ref is not None and now > w.ping_deadline]:
            self.lose(worker, hung=True)
            worker.ping_ref = None

    def shutdown(self) -> None:
        for worker in list(self._workers):
            self._drop(worker, kill=True)

    # ------------------------------------------------------------------ one iteration

    def score_population(
        self, theta_ref, seed: int, iteration: int = 0, should_stop: Callable[[], bool] = lambda: False
    ) -> IterationResult:
        """Scores of every chunk of the population (or ``min_fraction`` of them) at ``theta_ref``."""

        self._traffic = Traffic()
        self._warn_if_the_cluster_is_too_small()
        queue = _ChunkQueue(self, theta_ref, seed, iteration, self._traffic)
        checked = 0.0
        while not queue.enough():
            if should_stop():
                raise Interrupted()
            self.top_up()
            queue.dispatch()
            self._handle_answers(queue)
            now = time.time()
            if now >= checked + EXPIRY_CHECK_S:  # deadlines are seconds apart: not at every result
                checked = now
                self._expire_stale(now)
                self._expire_pings(now)
                queue.expire(now)
                self._check_for_live_workers(now)
        # min_fraction: stragglers finish in the background and are ignored, by their deadlines.
        for ref, (_, worker, deadline) in queue.in_flight.items():
            self._stale[ref] = (worker, deadline)
        return queue.result()

    def _handle_answers(self, queue: _ChunkQueue) -> None:
        """Waits up to POLL_S for the calls the pool is waiting on (chunks, starts, pings, compiles, stragglers),
        and takes each that is done."""
        starting = {w.ready_ref: w for w in self._workers if not w.ready}
        pinged = {w.ping_ref: w for w in self._workers if w.ping_ref is not None}
        compiling = {w.compile_ref: w for w in self._workers if w.compile_ref is not None}
        waitable = list(queue.in_flight) + list(starting) + list(pinged) + list(compiling) + list(self._stale)
        for ref in _all_ready(waitable):
            if ref in starting:
                self._started(starting[ref], ref)
            elif ref in pinged:
                self._pinged(pinged[ref])
            elif ref in compiling:
                self._compiled(compiling[ref])
            elif ref in self._stale:
                self._stale.pop(ref)[0].in_flight -= 1
            else:
                queue.collect(ref)

    def _check_for_live_workers(self, now: float) -> None:
        """Stops the run once it has had no live worker for ``--worker-wait-minutes``, saying what the cluster has."""
        if self.live_workers == 0 and self._wait.over(now):
            import ray

            available = ray.available_resources()
            needs = self._worker_needs()
            raise TrainingError(self._wait.gave_up(now, (
                f"each worker asks for {_resources(needs)}; the cluster has "
                f"{_resources({name: available.get(name, 0.0) for name in needs})} available")))

    def _worker_needs(self) -> dict[str, float]:
        """The Ray resources a worker asks for."""
        options = self._options
        return {"CPU": options.cpus_per_worker, "GPU": options.gpus_per_worker, **dict(options.worker_resources)}

    def _warn_if_the_cluster_is_too_small(self) -> None:
        """Once, at the first iteration: a line when the cluster cannot hold ``--workers`` workers at once (the
        metrics' ``workers`` then says how many are live)."""
        if self._cluster_checked or self._factory is not None:  # a factory's workers ask for what they like
            return
        self._cluster_checked = True
        import ray

        total = ray.cluster_resources()
        fits = {name: (int(total.get(name, 0.0) / need + 1e-9), need)
                for name, need in self._worker_needs().items() if need > 0}
        if not fits:
            return
        name, (most, need) = min(fits.items(), key=lambda item: item[1][0])
        if most < self._options.workers:
            _log.warning("pizero: warning: asked for %d workers of %g %s each; the cluster has %g %s in all: at "
                         "most %d can run at once", self._options.workers, need, name, total.get(name, 0.0), name,
                         most)

    @property
    def chunks_per_call(self) -> int:
        """Chunks handed to a worker in one call: ``--chunks-per-call``, whole launches (``check_against``), and
        never fewer than a launch's."""
        return max(self._options.chunks_per_call, self._config.chunks_per_launch)

    def gradient_parts(
        self, seed: int, weights: np.ndarray, owners: dict, compute_here: Callable[[int], np.ndarray],
        should_stop: Callable[[], bool] = lambda: False,
    ) -> tuple[list[np.ndarray], int]:
        """Every chunk's share of the pseudo-gradient, in chunk order, and how many were computed here.

        The worker that evaluated a chunk still holds its noise and returns the
        part without regenerating it; a chunk whose worker is gone, fails or
        does not answer within the chunk timeout is computed by
        ``compute_here`` (regenerating its noise): the same part either way.
        With GPU workers a lost chunk goes to a surviving worker first: only
        the same backend regenerates the same bits.
        Chunks whose weights are all zero (pairs dropped by ``min_fraction``)
        are always computed here; with ``gradient_on`` resolved to the
        driver, every chunk is (no worker is asked). ``should_stop`` is looked at every POLL_S
        and before each part computed here: a stop raises ``Interrupted``.
        """
        on_driver = self._options.gradient_on_driver(self._config.perturbation_rank)
        parts = {} if on_driver else self._collect_parts(self._ask_for_parts(seed, weights, owners), should_stop)
        if self._options.gpus_per_worker > 0 and not on_driver:
            # A CPU draws some normals a few ulps away from a GPU's (4.7% of them on an H200, docs/performance.md):
            # a surviving GPU worker regenerates a lost chunk's part, so the update stays bit-identical.
            lost = [index for index in range(self._config.num_chunks) if index not in parts]
            parts.update(self._collect_parts(self._ask_for_parts(seed, weights, self._survivors(lost)), should_stop))
        from_workers = len(parts)
        for index in range(self._config.num_chunks):
            if index not in parts:
                if should_stop():
                    raise Interrupted()
                parts[index] = compute_here(index)
        return [parts[index] for index in range(self._config.num_chunks)], self._config.num_chunks - from_workers

    def _survivors(self, chunks: list[int]) -> dict:
        """The pool's ready workers dealt round-robin over ``chunks``: {chunk index: worker}."""
        ready = [worker for worker in self._workers if worker.ready]
        return {index: ready[k % len(ready)] for k, index in enumerate(chunks)} if ready else {}

    def _ask_for_parts(self, seed: int, weights: np.ndarray, owners: dict) -> dict:
        """Asks each chunk's owner, if still in the pool, for the chunk's part: {ref: (chunk indices, owner)}.

        With ``--chunks-per-call`` above 1 a worker is asked for all its chunks' parts in calls of that many
        (``gradient_parts``), as it was handed them: fewer round trips, and on a GPU one program for each.
        """
        chunk, per_call = self._config.chunk_size, self.chunks_per_call
        by_owner: dict = {}
        for index in range(self._config.num_chunks):
            worker = owners.get(index)
            if worker is not None and worker in self._workers and weights[index * chunk:(index + 1) * chunk].any():
                by_owner.setdefault(worker, []).append(index)
        asked = {}
        for worker, indices in by_owner.items():
            for start in range(0, len(indices), per_call):
                call = tuple(indices[start:start + per_call])
                firsts = [index * chunk for index in call]
                if len(call) == 1:
                    args = (seed, firsts[0], weights[firsts[0]:firsts[0] + chunk])
                    ref = worker.actor.gradient_part.remote(*args)
                else:
                    args = (seed, firsts, np.stack([weights[first:first + chunk] for first in firsts]))
                    ref = worker.actor.gradient_parts.remote(*args)
                asked[ref] = call, worker
                self._traffic.to_workers += call_bytes(*args)
        return asked

    def _collect_parts(self, asked: dict, should_stop: Callable[[], bool]) -> dict[int, np.ndarray]:
        """The parts that come back within the chunk timeout: {chunk index: part}; the rest are left out, and a
        worker still on one past the timeout is hung: killed, as one past a chunk's deadline is."""
        import ray

        parts: dict[int, np.ndarray] = {}
        waiting = dict(asked)
        deadline = time.time() + self._options.chunk_timeout_s
        while waiting:
            if should_stop():
                raise Interrupted()
            left = deadline - time.time()
            # Past the deadline, one last look without waiting: a part that is in is no hang.
            ready_refs, _ = ray.wait(list(waiting), num_returns=len(waiting), timeout=max(0.0, min(POLL_S, left)))
            for ref in ready_refs:
                self._take_parts(ref, *waiting.pop(ref), parts)
            if left <= 0:
                break
        for worker in {worker: None for _, worker in waiting.values()}:
            self.lose(worker, hung=True)  # its parts are computed elsewhere
        return parts

    def _take_parts(self, ref, indices: tuple[int, ...], worker: _Worker, parts: dict[int, np.ndarray]) -> None:
        """A gradient-part call is done: its parts go into ``parts``, unless its worker died (lost)."""
        import ray
        from ray.exceptions import GetTimeoutError, RayError, RayTaskError

        try:
            answer = ray.get(ref, timeout=POLL_S)
        except RayTaskError as error:
            raise TrainingError(f"{_what(self._config)}: a worker failed computing chunk {indices[0]}'s gradient "
                                f"part: {task_failure(error)}") from None
        except GetTimeoutError:
            return  # (a RayError too) slow to fetch, not dead: the part is computed elsewhere
        except RayError:
            self.lose(worker)  # the worker died: the part is computed elsewhere
            return
        self._traffic.from_workers += serialized_bytes(answer)
        parts.update(zip(indices, answer if len(indices) > 1 else [answer]))


def _all_ready(refs: list) -> list:
    """The refs that are ready: waits up to POLL_S for one, then takes every other that is ready too.

    One result per pass would cost a pass (dispatch, the wait lists, the
    deadline checks) per chunk: with hundreds of workers in flight that pass
    grows with them, and thousands of chunks made the driver's time quadratic.
    """
    import ray

    if not refs:
        return []
    ready, rest = ray.wait(refs, num_returns=1, timeout=POLL_S)
    if ready and rest:
        ready += ray.wait(rest, num_returns=len(rest), timeout=0)[0]
    return ready


class _ChunkQueue:
    """One iteration's chunks: the queue, what is in flight where and until when, and what came back."""

    def __init__(self, pool: WorkerPool, theta_ref, seed: int, iteration: int, traffic: Traffic):
        self.pool, self.theta_ref, self.seed, self.iteration = pool, theta_ref, seed, iteration
        self.traffic = traffic
        self.theta_nodes: set[str] = set()  # nodes handed a chunk this iteration: each fetched the parameters once
        self._theta_bytes: int | None = None
        config, options = pool._config, pool._options
        self.chunk, self.num_chunks = config.chunk_size, config.num_chunks
        self.needed = self.num_chunks if options.min_fraction >= 1 else max(
            1, math.ceil(options.min_fraction * self.num_chunks))
        self.pending = deque(range(self.num_chunks))
        self.in_flight: dict = {}  # ref -> (chunk indices of the call, worker, deadline)
        self.results: dict[int, np.ndarray] = {}
        self.owners: dict[int, _Worker] = {}  # chunk index -> the worker that evaluated it (it kept the noise)
        self.failures: dict[int, int] = {}
        self.requeued = 0
        self.first_results: list[float] = []
        self.nodes: set[str] = set()

    def enough(self) -> bool:
        return len(self.results) >= self.needed

    def dispatch(self) -> None:
        """Hands pending chunks to ready workers, one each a round, up to ``in_flight_per_worker`` per device.

        Round by round, so that every idle worker has a chunk before any worker
        gets a second: depth first, 64 chunks on 128 workers went to 32 of them,
        two each, and took two rollouts' time instead of one.
        """
        options = self.pool._options
        open_workers = [w for w in self.pool._workers if w.ready and w.ping_ref is None]
        while self.pending and open_workers:
            open_workers = [w for w in open_workers
                            if w.in_flight < options.in_flight_per_worker * w.info.get("devices", 1)]
            for worker in open_workers:
                if not self.pending:
                    break
                count = min(self.pool.chunks_per_call, len(self.pending))
                self._hand(worker, tuple(self.pending.popleft() for _ in range(count)))

    def _hand(self, worker: _Worker, indices: tuple[int, ...]) -> None:
        """Chunks ``indices`` to ``worker`` in one call, with its deadline (and, in a chaos run, the kill
        scheduled for one of them). One chunk goes as ``score_chunk``, several as ``score_chunks``."""
        options = self.pool._options
        devices = worker.info.get("devices", 1)  # calls the worker runs at once
        firsts = [index * self.chunk for index in indices]
        call, first_pairs = ((worker.actor.score_chunk, firsts[0]) if len(indices) == 1
                             else (worker.actor.score_chunks, firsts))
        ref = call.remote(self.theta_ref, self.seed, first_pairs)
        self._count_dispatch(worker, first_pairs)
        # The deadline allows for the calls queued ahead of this one on the worker, and for each chunk in it.
        deadline = time.time() + options.chunk_timeout_s * len(indices) * (worker.in_flight // devices + 1)
        self.in_flight[ref] = (indices, worker, deadline)
        worker.in_flight += 1
        scheduled = {(self.iteration, index) for index in indices} & (options.kill_schedule - self.pool._kills_done)
        if scheduled:
            self.pool._kills_done.update(scheduled)
            self.pool.kill_process(worker)

    def _count_dispatch(self, worker: _Worker, first_pairs) -> None:
        """The bytes a call sends out: its arguments, and the parameters if its worker's node has not fetched them."""
        self.traffic.to_workers += call_bytes(self.theta_ref, self.seed, first_pairs)
        node = worker.info.get("node_id", "?")
        if node not in self.theta_nodes:
            import ray

            if self._theta_bytes is None:  # the driver's own object: ray.get maps it, copying nothing
                self._theta_bytes = serialized_bytes(ray.get(self.theta_ref))
            self.theta_nodes.add(node)
            self.traffic.to_workers += self._theta_bytes

    def collect(self, ref) -> None:
        """A call's results are in: its chunks' scores, or its worker died and its chunks go back on the queue."""
        import ray
        from ray.exceptions import GetTimeoutError, RayError, RayTaskError

        indices, worker, _ = self.in_flight.pop(ref)
        worker.in_flight -= 1
        try:
            returned = ray.get(ref, timeout=self.pool._options.chunk_timeout_s)
        except RayTaskError as error:
            raise TrainingError(f"{_what(self.pool._config)}: a worker failed evaluating chunks {list(indices)}: "
                                f"{task_failure(error)}") from None
        except GetTimeoutError:  # (a RayError too) its result is in but cannot be fetched: killed as hung
            self._fail(indices, worker, hung=True)
            return
        except RayError:
            self._fail(indices, worker, hung=False)  # the worker died (or its node did): the chunks run elsewhere
            return
        self.traffic.from_workers += serialized_bytes(returned)
        for index, scores in zip(indices, [returned] if len(indices) == 1 else returned, strict=True):
            self.results[index] = scores
            self.owners[index] = worker
        self.nodes.add(worker.info.get("node_id", "?"))
        if worker.first_result_s is None:
            worker.first_result_s = time.time() - worker.created
            self.first_results.append(worker.first_result_s)

    def expire(self, now: float) -> None:
        """Kills workers past a chunk's deadline (hung) and requeues the chunks of every dropped worker."""
        import ray

        expired = [ref for ref, (_, _, deadline) in self.in_flight.items() if now > deadline]
        if expired:  # a result that is in but not yet collected (one per ray.wait) is no hang
            done, _ = ray.wait(expired, num_returns=len(expired), timeout=0, fetch_local=False)
            for ref in set(expired) - set(done):
                indices, worker, _ = self.in_flight.pop(ref)
                self._fail(indices, worker, hung=True)
        for ref, (indices, worker, _) in list(self.in_flight.items()):
            if worker not in self.pool._workers:  # dropped: its other chunks go back too
                del self.in_flight[ref]
                self.pending.extendleft(reversed(indices))
                self.requeued += len(indices)

    def _fail(self, indices: tuple[int, ...], worker: _Worker, hung: bool) -> None:
        """The worker died or ``hung`` on the call of chunks ``indices``: they go back, first in line; the worker
        is lost."""
        for index in indices:
            self.failures[index] = self.failures.get(index, 0) + 1
            if self.failures[index] >= MAX_CHUNK_FAILURES:
                raise TrainingError(f"chunk {index} failed on {self.failures[index]} workers; giving up")
        self.pending.extendleft(reversed(indices))
        self.requeued += len(indices)
        self.pool.lose(worker, hung=hung)

    def result(self) -> IterationResult:
        population = self.num_chunks * self.chunk
        scores = np.zeros((population, 2), np.float32)
        valid = np.zeros((population,), bool)
        for index, chunk_scores in self.results.items():
            scores[index * self.chunk:(index + 1) * self.chunk] = chunk_scores
            valid[index * self.chunk:(index + 1) * self.chunk] = True
        return IterationResult(scores, valid, self.requeued, self.first_results, sorted(self.nodes), self.owners,
                               self.traffic)
