"""Ray worker actors: each holds the compiled population rollout and scores chunks.

A worker compiles its rollout ahead of time in ``__init__`` (a hit in JAX's
persistent compilation cache when another worker compiled the same program
before), so "ready" means "can return a chunk in one rollout's time", and the
driver's per-chunk timeout need not allow for compiles.

A CPU worker with N CPUs runs N JAX CPU devices and scores up to N chunks
at once, one per device (``chunk_scoring``); a GPU worker uses the GPUs Ray
gave it the same way. Its first device compiles before it is ready, the others
after: ``ready`` says how many devices have compiled so far, and ``compiled``
answers once the others have compiled or failed to, with the devices it runs
on then.
"""

from __future__ import annotations

import os
import time
from typing import Any, Callable, NamedTuple

import numpy as np
import ray

from pizero_ray.trainer import chunk_scoring


class RolloutWorker:
    """Evaluates chunks of antithetic pairs; returns their scores [C, 2] as float32."""

    def __init__(self, config_json: str, compile_cache_dir: str | None, cpu_devices: int = 1, pin_cores: bool = False,
                 cpu_only: bool = False, keep_noise: bool = True):
        started = time.time()
        from pizero_ray.trainer import compile_cache

        self._cores = chunk_scoring.CoreClaim.claim(cpu_devices) if pin_cores else chunk_scoring.CoreClaim((), [])
        if cpu_only:  # a CPU worker on a GPU node must not grab the GPU
            chunk_scoring.use_cpu_only()
        chunk_scoring.configure_cpu_devices(cpu_devices)  # before JAX's first computation
        compile_cache.enable(compile_cache_dir)
        from pizero_ray.config import Config

        self.config = Config.from_json(config_json)
        self._chunks = chunk_scoring.ChunkScorer(self.config, keep_noise=keep_noise)
        self._info = {
            "pid": os.getpid(),
            "node_id": ray.get_runtime_context().get_node_id(),
            "device": str(self._chunks.devices[0]),
            "pinned_cores": list(self._cores.cores),
            "startup_s": time.time() - started,
        }

    def ready(self) -> dict:
        """Where this worker runs, and ``ChunkScorer.compile_report``: the devices compiled so far ("devices"),
        and whether others still compile ("compiling")."""
        return {**self._info, **self._chunks.compile_report()}

    def compiled(self) -> dict:
        """``ready`` once every device's compile is over: "devices" is how many calls the worker runs at once,
        "compile_error" the error of a device that failed to compile, or None."""
        self._chunks.wait_for_compiles()
        return self.ready()

    def peak_rss_mb(self) -> float:
        """This worker process's peak resident memory (for `pizero bench`)."""
        return chunk_scoring.peak_rss_mb()

    def score_chunk(self, theta: np.ndarray, iteration_seed: int, first_pair: int) -> np.ndarray:
        return self._chunks.score(theta, iteration_seed, first_pair)

    def score_chunks(self, theta: np.ndarray, iteration_seed: int, first_pairs: list[int]) -> list[np.ndarray]:
        """Several chunks in one call (``--chunks-per-call``) on one device, started together; each scores as
        ``score_chunk`` would."""
        return self._chunks.score_many(theta, iteration_seed, first_pairs)

    def gradient_part(self, iteration_seed: int, first_pair: int, weights: np.ndarray) -> np.ndarray:
        """The chunk's share of the pseudo-gradient, from the noise kept while evaluating it."""
        return self._chunks.gradient_part(iteration_seed, first_pair, weights)

    def gradient_parts(self, iteration_seed: int, first_pairs: list[int], weights: np.ndarray) -> list[np.ndarray]:
        """Several chunks' shares (weights [n, C]) in one call, each as ``gradient_part`` gives it."""
        return self._chunks.gradient_parts(iteration_seed, first_pairs, weights)


def start_worker(
    config_json: str, num_cpus: float, num_gpus: float, compile_cache_dir: str | None, resources: dict | None = None,
    pin_cores: bool = True, keep_noise: bool = True,
):
    """A worker actor; a CPU worker pins itself to cores of its own if it can (``chunk_scoring.CoreClaim``).

    ``keep_noise``: the worker keeps each chunk's noise for the chunk's gradient
    part; False where the driver forms every part (``--gradient-on`` resolved
    to the driver) and no worker is ever asked for one.

    A CPU worker sets its JAX platform itself, in ``__init__``: an actor without
    a ``runtime_env`` can start in one of Ray's pre-started worker processes,
    where one with environment variables of its own waits for a new process to
    start (a tiny config's worker was ready in 3.5 s instead of 4.3 s on a
    2-core machine). Workers sharing a GPU keep the one variable that must be
    set before their process starts.
    """
    devices = worker_devices(num_cpus, num_gpus)
    actor = ray.remote(RolloutWorker).options(
        # A call per device, and one for ``compiled``, which waits for the compiles without holding a device's.
        num_cpus=num_cpus, num_gpus=num_gpus, resources=resources or {}, max_concurrency=devices + 1,
        runtime_env=_gpu_env(num_gpus))
    if num_gpus > 0:
        return actor.remote(config_json, compile_cache_dir, keep_noise=keep_noise)
    return actor.remote(config_json, compile_cache_dir, devices, pin_cores, cpu_only=True, keep_noise=keep_noise)


def _gpu_env(num_gpus: float) -> dict | None:
    """Workers sharing a GPU (--gpus-per-worker 0.5): JAX's default of taking 75% of the GPU at start would leave
    the second one too little."""
    if 0 < num_gpus < 1:
        return {"env_vars": {"XLA_PYTHON_CLIENT_PREALLOCATE": "false"}}
    return None


def worker_devices(num_cpus: float, num_gpus: float) -> int:
    """How many chunks a worker runs at once: one per whole CPU (CPU workers) or per whole GPU."""
    return max(1, int(num_gpus if num_gpus > 0 else num_cpus))


def stop_worker(actor) -> None:
    """Ends a worker actor (it is not restarted)."""
    ray.kill(actor, no_restart=True)


class WorkerFactory(NamedTuple):
    """How a pool starts and stops its workers, if not as ``RolloutWorker`` actors (``start_worker``,
    ``stop_worker``): the scale model's stub workers (``pizero_ray.bench.stub_workers``) come this way."""

    start: Callable[..., Any]  # start_worker's arguments -> a handle with ready/score_chunk/gradient_part .remote
    stop: Callable[[Any], None]
