"""Stub workers: Ray actors that import no JAX and answer each chunk after a modelled delay.

The scale model (``bench.scale``) runs the real driver and the real
``WorkerPool`` against them, and the fault tests kill them. They answer the
calls a ``RolloutWorker`` answers (``ready``, ``score_chunk``,
``gradient_part``):
- a chunk's scores come after ``delay_s`` (the modelled rollout), a pure
  function of (iteration seed, first pair) and untied, so a run's parameters do
  not depend on which stub scored which chunk, or how many were killed;
- a gradient part, where one is asked for, is ``parameters`` zeros: its size is
  what the scale model measures (with parts formed on the driver, none is).
The parameters a chunk's call names are fetched to the stub's node before the
call runs, as for a real worker, and a worker runs one chunk at a time, as one
device does (the pool keeps two in flight per device).

One process can stand in for many workers (``StubWorkers(processes=...)``):
an asyncio actor serves its workers' chunks at once, each after its delay, so a
machine with room for tens of actor processes drives a pool of hundreds, and a
later pool reuses the processes. Stand-ins are for timing: their processes
live until ``shutdown``, and killing one would take all its stand-ins.
"""

from __future__ import annotations

import asyncio
import os
from typing import Any, Callable, NamedTuple

import numpy as np


def stub_scores(seed: int, first_pair: int, chunk_size: int) -> np.ndarray:
    """Scores [chunk_size, 2] of the pairs from ``first_pair`` on: normal draws seeded by (seed, first pair)."""
    return np.random.default_rng([int(seed), int(first_pair)]).standard_normal((chunk_size, 2)).astype(np.float32)


class StubWorker:
    """One process's stub: it answers for every worker that stands in on it (an asyncio actor)."""

    def __init__(self, chunk_size: int, parameters: int, delay_s: float):
        self._chunk_size, self._parameters, self._delay_s = chunk_size, parameters, delay_s
        self._busy: dict[int, asyncio.Lock] = {}  # per stand-in: a worker runs one chunk at a time, as on a device

    def ready(self, stand_in: int = 0) -> dict:
        import ray

        return {"pid": os.getpid(), "node_id": ray.get_runtime_context().get_node_id(), "devices": 1,
                "stand_in": stand_in}

    async def score_chunk(self, theta, seed: int, first_pair: int, stand_in: int = 0) -> np.ndarray:
        async with self._busy.setdefault(stand_in, asyncio.Lock()):
            await asyncio.sleep(self._delay_s)
        return stub_scores(seed, first_pair, self._chunk_size)

    async def score_chunks(self, theta, seed: int, first_pairs: list[int], stand_in: int = 0) -> list[np.ndarray]:
        async with self._busy.setdefault(stand_in, asyncio.Lock()):
            await asyncio.sleep(self._delay_s * len(first_pairs))
        return [stub_scores(seed, first_pair, self._chunk_size) for first_pair in first_pairs]

    async def gradient_part(self, seed: int, first_pair: int, weights: np.ndarray) -> np.ndarray:
        return np.zeros(self._parameters, np.float32)

    async def gradient_parts(self, seed: int, first_pairs: list[int], weights: np.ndarray) -> list[np.ndarray]:
        return [np.zeros(self._parameters, np.float32) for _ in first_pairs]


class _Call(NamedTuple):
    """A stand-in's method: ``.remote(...)`` calls its process's actor."""

    remote: Callable[..., Any]


class StandIn:
    """A worker handle for the pool, served by a process that other stand-ins share."""

    def __init__(self, actor, stand_in: int):
        self.actor, self.stand_in = actor, stand_in
        self.ready = _Call(lambda: actor.ready.remote(stand_in))
        self.score_chunk = _Call(lambda theta, seed, first_pair: actor.score_chunk.remote(
            theta, seed, first_pair, stand_in=stand_in))
        self.score_chunks = _Call(lambda theta, seed, first_pairs: actor.score_chunks.remote(
            theta, seed, first_pairs, stand_in=stand_in))
        self.gradient_part = _Call(actor.gradient_part.remote)
        self.gradient_parts = _Call(actor.gradient_parts.remote)


class StubWorkers:
    """A ``workers.WorkerFactory``'s two functions for stub workers: ``start`` and ``stop``.

    ``processes`` None: one actor process per worker. Else at most that many
    processes; worker k stands in on process k mod ``processes``.
    """

    def __init__(self, chunk_size: int, parameters: int, delay_s: float, processes: int | None = None):
        self._args = (chunk_size, parameters, delay_s)
        self._processes = processes
        self._actors: list = []  # the processes, in start order
        self.started = 0

    def start(self, config_json: str, num_cpus: float, num_gpus: float, compile_cache_dir: str | None,
              resources: dict | None = None, pin_cores: bool = True, keep_noise: bool = True):
        """``workers.start_worker``'s arguments; a stub heeds only the custom node resources asked for."""
        import ray

        index = self.started if self._processes is None else self.started % self._processes
        self.started += 1
        if index == len(self._actors):
            options = {"num_cpus": 0, "max_concurrency": 100_000, "resources": resources or {}}
            self._actors.append(ray.remote(StubWorker).options(**options).remote(*self._args))
        actor = self._actors[index]
        return actor if self._processes is None else StandIn(actor, self.started - 1)

    def stop(self, handle) -> None:
        """Ends a worker's process; a stand-in's lives on for the others (``shutdown`` ends it)."""
        import ray

        if not isinstance(handle, StandIn):
            ray.kill(handle, no_restart=True)

    def shutdown(self) -> None:
        import ray

        for actor in self._actors:
            ray.kill(actor, no_restart=True)

    def factory(self):
        from pizero_ray.trainer.workers import WorkerFactory

        return WorkerFactory(self.start, self.stop)
