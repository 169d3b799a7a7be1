"""A worker's local compute: every device at once, the noise it kept, the cores it holds.

XLA's CPU backend runs the rollout's many small operations (the search's
while loops, member-sized products) on one thread, so a process with one CPU
device leaves its other cores partly idle. A process with N cores therefore
asks JAX for N CPU devices (``configure_cpu_devices``) and runs whole chunks
on all of them concurrently (``ChunkScorer``). Each device runs the same
single-device program on a whole chunk, so a chunk's scores do not depend on
which device, or how many, computed it: the trainer stays deterministic
whatever its workers' sizes. On a GPU node the devices are the GPUs the
process may see. The scorer keeps each chunk's noise for the chunk's share
of the gradient (``ChunkCache``), and ``CoreClaim`` keeps worker processes off
each other's cores.
"""

from __future__ import annotations

import os
import queue
import resource
import tempfile
import threading
from pathlib import Path
from typing import Sequence

import numpy as np

from pizero_ray.config import Config

# A worker keeps each chunk's noise until the driver asks for the chunk's share
# of the gradient (saving the driver its regeneration), up to this many bytes:
# 40 pairs of the bench agent's full-rank noise take 8.7 MB.
NOISE_CACHE_BYTES = 1 << 30
# Iterations whose noise a worker keeps: the newest seeds it has seen. Two, so
# that a straggler of the last iteration (dropped by min_fraction, finishing
# late) cannot push out the current one's noise; an iteration two back is over.
KEPT_SEEDS = 2
SEEDS_REMEMBERED = 64  # seeds known to be old: a straggler of theirs is not mistaken for a new iteration


def use_cpu_only() -> None:
    """This process's JAX uses only its CPU backend, as JAX_PLATFORMS=cpu would; call before JAX's first computation."""
    import jax

    jax.config.update("jax_platforms", "cpu")


def configure_cpu_devices(count: int) -> None:
    """Gives this process's JAX CPU backend ``count`` devices; call before JAX's first computation."""
    import jax

    jax.config.update("jax_num_cpu_devices", max(1, int(count)))


def peak_rss_mb() -> float:
    """This process's peak resident memory (Linux reports ``ru_maxrss`` in KiB)."""
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def cpu_count() -> int:
    """The cores this process may run on (its affinity mask, not the machine's total)."""
    return len(os.sched_getaffinity(0))


class CoreClaim:
    """Cores this process holds for itself: one lock file per core, released when the process ends.

    Two unpinned JAX processes on a node run at about half speed each (measured:
    two 1-CPU workers sharing 2 cores took 0.50 s per chunk pair where each
    pinned to its own core took 0.28 s), so a worker claims as many cores as it
    has CPUs and pins itself to them. The locks are ``flock``s: a killed worker
    frees its cores at once, with nothing to clean up.
    """

    def __init__(self, cores: tuple[int, ...], lock_fds: list[int], unpinned: tuple[int, ...] = ()):
        self.cores = cores
        self._lock_fds = lock_fds  # open for the claim's (the worker's) lifetime
        self._unpinned = unpinned  # the affinity before the claim

    def release(self) -> None:
        """Gives the cores back before the process ends (a process that goes on to other work)."""
        for fd in self._lock_fds:
            os.close(fd)
        self._lock_fds = []
        if self._unpinned:
            os.sched_setaffinity(0, self._unpinned)

    @classmethod
    def claim(cls, count: int, lock_dir: str | os.PathLike | None = None) -> CoreClaim:
        """Pins this process to ``count`` cores no other claimant on this machine holds.

        Claims nothing (an empty claim, the process left as it was) when it
        would be all the cores anyway, or when not enough are free.
        """
        import fcntl

        allowed = sorted(os.sched_getaffinity(0))
        if count >= len(allowed):
            return cls((), [])
        directory = Path(lock_dir) if lock_dir else Path(tempfile.gettempdir()) / "pizero-ray-cores"
        held: list[tuple[int, int]] = []
        try:
            directory.mkdir(parents=True, exist_ok=True)
            for core in allowed:
                fd = os.open(directory / f"core-{core}.lock", os.O_CREAT | os.O_RDWR, 0o666)
                try:
                    fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                except OSError:
                    os.close(fd)
                    continue
                held.append((core, fd))
                if len(held) == count:
                    break
        except OSError:  # an unwritable lock dir: run unpinned
            pass
        if len(held) < count:
            for _, fd in held:
                os.close(fd)
            return cls((), [])
        cores = tuple(core for core, _ in held)
        os.sched_setaffinity(0, cores)
        return cls(cores, [fd for _, fd in held], tuple(allowed))


class ChunkCache:
    """What a worker keeps of each chunk by (iteration seed, first pair): its noise, or the scores of a chunk
    launched before it was asked for; for the newest ``KEPT_SEEDS`` seeds, up to a byte cap.

    A seed's chunks are dropped once ``KEPT_SEEDS`` newer seeds have been seen,
    so the noise of chunks whose parts are never asked for (stragglers, chunks
    whose parts the driver computed itself) does not pile up; a straggler of a
    seed already dropped (one of the last ``SEEDS_REMEMBERED`` seen) is not kept.
    """

    def __init__(self, chunk_bytes: int, max_bytes: int | None = None):
        self._chunk_bytes = chunk_bytes
        self._max_bytes = NOISE_CACHE_BYTES if max_bytes is None else max_bytes
        self._lock = threading.Lock()
        self._seeds: list[int] = []  # seeds seen, oldest first; the last KEPT_SEEDS are kept
        self._kept: dict[tuple[int, int], object] = {}
        self.misses = 0  # chunks asked for that were not here

    def keep(self, seed: int, first_pair: int, value) -> None:
        with self._lock:
            if seed not in self._seeds:  # a new iteration: the oldest kept one is over
                self._seeds = (self._seeds + [seed])[-SEEDS_REMEMBERED:]
                kept = set(self._seeds[-KEPT_SEEDS:])
                self._kept = {key: value for key, value in self._kept.items() if key[0] in kept}
            if seed not in self._seeds[-KEPT_SEEDS:]:  # a straggler of an iteration that is over
                return
            if (len(self._kept) + 1) * self._chunk_bytes <= self._max_bytes:
                self._kept[(seed, first_pair)] = value

    def take(self, seed: int, first_pair: int):
        """What was kept of the chunk (given up: a chunk is asked for once), or None."""
        with self._lock:
            value = self._kept.pop((seed, first_pair), None)
            self.misses += value is None
            return value

    def __len__(self) -> int:
        return len(self._kept)


class ChunkScorer:
    """The population rollout compiled for each local device: ``score`` one chunk, ``score_many``, or ``score_all``.

    The unit of a device call is a launch: ``config.chunks_per_launch``
    chunks, grouped by index, whichever of them are asked for (the others'
    scores wait for their call). ``score`` may be called from several threads
    at once (a threaded Ray actor): each call borrows a free device for the
    launch's duration, and keeps each chunk's noise for ``gradient_part``
    (unless ``keep_noise`` is False: where the driver forms every part, nobody
    asks). The noise is made on the device by ``es.GradientParts.noise``, the
    function that regenerates it anywhere else, compiled for each device as
    the rollout is; the rollout takes it as an input.
    """

    def __init__(self, config: Config, max_devices: int | None = None, keep_noise: bool = True):
        import jax
        import jax.numpy as jnp
        from jax.sharding import SingleDeviceSharding

        from pizero_ray import envs, es
        from pizero_ray.es import population

        self.config = config
        env = envs.make(config.env, **config.env_kwargs())
        layout = population.params_layout(config, env)  # theta comes with each chunk
        self.parameters = layout.size
        self.agent_steps_per_pair = 2 * config.episodes_per_member * env.spec.horizon
        self.devices = jax.local_devices()[:max_devices]
        pair_scores = population.make_pair_scorer(config, env, layout)
        self._parts = es.gradient_parts(config, layout.perturbation)
        chunk_noise_bytes = config.chunk_size * layout.perturbation.noise_size * 4
        self._kept = ChunkCache(chunk_noise_bytes, max_bytes=None if keep_noise else 0)  # 0: keeps nothing
        # Scores of chunks launched with one asked for, until they are asked for too (a chunk handed on alone,
        # after a fault, still runs its whole launch: its scores are that launch's).
        self._spare_scores = ChunkCache(config.chunk_size * 2 * 4)
        self._launch_pairs = config.chunk_size * config.chunks_per_launch
        self.launches_run = 0  # device calls of the rollout so far

        def compile_for(device):
            """The noise and score programs for one launch (``chunks_per_launch`` chunks) on ``device``."""
            on = SingleDeviceSharding(device)
            seed = jax.ShapeDtypeStruct((), jnp.uint32, sharding=on)
            chunks = config.chunks_per_launch
            pairs = chunks * config.chunk_size
            make_noise = self._parts.noise if chunks == 1 else _launch_noise(self._parts.noise, chunks,
                                                                             config.chunk_size)
            noise = make_noise.lower(seed, jax.ShapeDtypeStruct((), jnp.int32, sharding=on)).compile()
            scores = pair_scores.lower(
                jax.ShapeDtypeStruct((layout.size,), jnp.float32, sharding=on),
                seed,
                jax.ShapeDtypeStruct((pairs,), jnp.int32, sharding=on),
                jax.ShapeDtypeStruct((pairs, layout.perturbation.noise_size), jnp.float32, sharding=on),
            ).compile()
            return noise, scores

        # The first device's programs are compiled now, so that a worker is ready
        # as soon as it can return a chunk; the others (the same programs for
        # another device: compiles side by side were no faster) follow in the
        # background and join the free list as they are done.
        self._jax = jax
        self._free: queue.SimpleQueue[int] = queue.SimpleQueue()
        self._compiled = [compile_for(self.devices[0])] + [None] * (len(self.devices) - 1)
        self._free.put(0)
        self._compile_error: BaseException | None = None
        self._compiling = threading.Thread(target=self._compile_others, args=(compile_for,), daemon=True)
        self._compiling.start()

    def _compile_others(self, compile_for) -> None:
        try:
            for index in range(1, len(self.devices)):
                self._compiled[index] = compile_for(self.devices[index])
                self._free.put(index)
        except BaseException as error:  # the worker goes on with the devices that compiled (compile_report)
            self._compile_error = error

    def wait_for_compiles(self) -> None:
        """Returns once every device's compile is over, whether it succeeded or not (``compile_report``)."""
        self._compiling.join()

    def compile_report(self) -> dict:
        """{"devices": devices compiled so far (the calls this scorer runs at once), "local_devices": all of
        them, "compiling": whether others still compile, "compile_error": a failed compile's error, or None}."""
        compiling = self._compiling.is_alive()  # first: once it is over, the count below is final
        error = self._compile_error
        return {"devices": sum(programs is not None for programs in self._compiled),
                "local_devices": self.num_devices, "compiling": compiling,
                "compile_error": None if error is None else f"{type(error).__name__}: {error}"}

    def wait_until_compiled(self) -> None:
        """Returns once every device's program is compiled (raises if one failed)."""
        self.wait_for_compiles()
        if self._compile_error is not None:
            raise RuntimeError(f"compiling the rollout for another device failed: {self._compile_error}")

    @property
    def num_devices(self) -> int:
        return len(self.devices)

    @property
    def regenerated_parts(self) -> int:
        """Gradient parts this scorer had to regenerate the noise for (it had not kept it)."""
        return self._kept.misses

    def _dispatch(self, index: int, theta, seed: int, launch_first: int):
        """Starts the launch whose first pair is ``launch_first`` on device ``index``; returns its (not yet ready)
        scores and noise, its chunks' rows one after another."""
        self.launches_run += 1
        device = self.devices[index]
        pairs = np.arange(launch_first, launch_first + self._launch_pairs, dtype=np.int32)
        put = self._jax.device_put
        make_noise, score = self._compiled[index]
        seed = put(np.uint32(seed), device)
        noise = make_noise(seed, put(np.int32(launch_first), device))
        return score(put(theta, device), seed, put(pairs, device), noise), noise

    def _launch_of(self, first_pair: int) -> int:
        return first_pair - first_pair % self._launch_pairs

    def _launches_of(self, first_pairs) -> list[int]:
        """The launches that hold these chunks, each once, in the order first asked for."""
        return list(dict.fromkeys(self._launch_of(first) for first in first_pairs))

    def _chunk_rows(self, launch_rows: np.ndarray, first_pair: int) -> np.ndarray:
        """A chunk's rows [chunk_size, ...] of its launch's (the launch's chunks one after another)."""
        offset = first_pair % self._launch_pairs
        return launch_rows[offset:offset + self.config.chunk_size]

    def score(self, theta: np.ndarray, seed: int, first_pair: int) -> np.ndarray:
        """Scores [chunk_size, 2] of the pairs from ``first_pair`` on, on whichever device is free."""
        return self.score_many(theta, seed, [first_pair])[0]

    def score_many(self, theta: np.ndarray, seed: int, first_pairs: Sequence[int]) -> list[np.ndarray]:
        """Chunks' scores [chunk_size, 2] on one free device: the parameters go to it once, and each launch
        (``chunks_per_launch`` chunks, grouped by index) that holds a chunk asked for is started before the
        first result is waited for. A launch's other chunks keep their scores until asked for; every launched
        chunk keeps its noise for its gradient part. A chunk's scores are its launch's, however it is asked
        for: the parameters do not depend on how chunks are handed out.
        """
        size = self.config.chunk_size
        scores = {first: self._spare_scores.take(seed, first) for first in first_pairs}
        launches = self._launches_of(first for first, got in scores.items() if got is None)
        if not launches:
            return [scores[first] for first in first_pairs]
        index = self._free.get()
        try:
            on_device = self._jax.device_put(np.asarray(theta, np.float32), self.devices[index])
            started = [(launch, self._dispatch(index, on_device, seed, launch)) for launch in launches]
            launched = {launch: np.asarray(launch_scores, np.float32) for launch, (launch_scores, _) in started}
        finally:
            self._free.put(index)
        whole = self.config.chunks_per_launch == 1
        for launch, (_, noise) in started:
            for first in range(launch, launch + self._launch_pairs, size):
                rows = self._chunk_rows(launched[launch], first)
                if first not in scores:
                    self._spare_scores.keep(seed, first, rows)
                elif scores[first] is None:
                    scores[first] = rows
                self._kept.keep(seed, first, noise if whole else self._chunk_rows(noise, first))
        return [scores[first] for first in first_pairs]

    def gradient_part(self, seed: int, first_pair: int, weights: np.ndarray) -> np.ndarray:
        """The chunk's share sum_i w_i z_i [D], from the noise kept while evaluating it, else regenerated."""
        noise = self._kept.take(seed, first_pair)
        if noise is None:
            return self._parts.regenerated(seed, first_pair, weights)
        return self._parts.from_noise(weights, noise)

    def gradient_parts(self, seed: int, first_pairs: Sequence[int], weights: np.ndarray) -> list[np.ndarray]:
        """Several chunks' parts in one call (weights [n, C]): the same parts as ``gradient_part`` of each.

        With low-rank noise the kept noise of the chunks evaluated on one device
        goes through one program (``GradientParts.many``): on a GPU a part is a
        loop of C r trips, so a part per chunk would cost a loop per chunk.
        """
        weights = np.asarray(weights, np.float32)
        kept = {first: self._kept.take(seed, first) for first in first_pairs}
        parts: dict[int, np.ndarray] = {}
        by_device: dict = {}
        for i, first in enumerate(first_pairs):
            noise = kept[first]
            if noise is None:
                parts[first] = self._parts.regenerated(seed, first, weights[i])
            elif self._parts.many is None:
                parts[first] = self._parts.from_noise(weights[i], noise)
            else:
                by_device.setdefault(next(iter(noise.devices())), []).append(i)
        for rows in by_device.values():
            noise = self._jax.numpy.stack([kept[first_pairs[i]] for i in rows])
            together = np.asarray(self._parts.many(weights[rows], noise), np.float32)
            parts.update({first_pairs[i]: part for i, part in zip(rows, together)})
        return [parts[first] for first in first_pairs]

    def score_all(self, theta: np.ndarray, seed: int, first_pairs: Sequence[int]) -> list[np.ndarray]:
        """Many chunks, their launches dealt round-robin over the devices and run concurrently (one thread)."""
        self.wait_until_compiled()
        theta = np.asarray(theta, np.float32)
        on_device = [self._jax.device_put(theta, device) for device in self.devices]
        launches = self._launches_of(first_pairs)
        pending = {launch: self._dispatch(i % self.num_devices, on_device[i % self.num_devices], seed, launch)[0]
                   for i, launch in enumerate(launches)}
        launched = {launch: np.asarray(scores, np.float32) for launch, scores in pending.items()}
        return [self._chunk_rows(launched[self._launch_of(first)], first) for first in first_pairs]


def _launch_noise(chunk_noise, chunks: int, chunk_size: int):
    """jit(seed, first_pair) -> the noise of ``chunks`` consecutive chunks [chunks * chunk_size, noise_size]:
    ``chunk_noise`` of each chunk (the function that regenerates it anywhere), one after another."""
    import jax
    import jax.numpy as jnp

    def noise(seed, first_pair):
        firsts = first_pair + chunk_size * jnp.arange(chunks, dtype=jnp.int32)
        drawn = jax.vmap(chunk_noise, in_axes=(None, 0))(seed, firsts)
        return drawn.reshape(chunks * chunk_size, drawn.shape[-1])

    return jax.jit(noise)
