"""The unit costs the scale model is built from, measured here: Ray's per-call cost, its per-byte costs, and
the driver's update as the parameters grow.

Ray's release benchmarks (``ray/release/microbenchmark``) time actor calls
two ways, and so does ``call_costs``: one call at a time (submit, wait for the
answer: the latency of one round trip) and many in flight at once from one
caller (the caller's throughput: what a driver handing out thousands of chunks
pays per call). ``byte_costs`` times what moving D float32 parameters costs:
putting them in the driver's object store, a worker on another node fetching
them (the parameters each iteration), and the driver fetching a worker's D
floats (a gradient part). ``update_costs`` times the driver's own arithmetic at
D parameters: Adam's step over the summed parts, and one chunk's part formed
from regenerated noise (rank 0 and rank 1).
"""

from __future__ import annotations

import statistics
import time

import numpy as np


class _Echo:
    """The smallest useful actor: answers at once; hands back or takes in arrays of a given size."""

    def noop(self) -> int:
        return 0

    def zeros(self, size: int) -> np.ndarray:
        return np.zeros(size, np.float32)

    def size_of(self, array: np.ndarray) -> int:
        return int(array.size)

    def node(self) -> str:
        import ray

        return ray.get_runtime_context().get_node_id()


def _echo(resources: dict | None = None):
    import ray

    return ray.remote(_Echo).options(num_cpus=0, resources=resources or {}).remote()


def _median_s(fn, repeats: int) -> float:
    times = []
    for _ in range(repeats):
        started = time.perf_counter()
        fn()
        times.append(time.perf_counter() - started)
    return statistics.median(times)


def call_costs(calls: int = 2000, actors: int = 8) -> dict:
    """Seconds per actor call: one round trip at a time, and per call with ``calls`` in flight over ``actors``."""
    import ray

    echoes = [_echo() for _ in range(actors)]
    ray.get([echo.noop.remote() for echo in echoes])
    round_trip = _median_s(lambda: ray.get(echoes[0].noop.remote()), 200)

    def many():
        ray.get([echoes[k % actors].noop.remote() for k in range(calls)])

    many()
    in_flight = _median_s(many, 3) / calls
    for echo in echoes:
        ray.kill(echo)
    return {"call_round_trip_s": round_trip, "call_in_flight_s": in_flight, "call_in_flight_actors": actors}


def byte_costs(sizes: tuple[int, ...], remote_resources: dict) -> list[dict]:
    """Per size D (float32 elements): ray.put in the driver, a fetch by an actor on another node (a node
    holding ``remote_resources``), and the driver's fetch of D floats an actor on that node returns."""
    import ray

    remote = _echo(remote_resources)
    assert ray.get(remote.node.remote()) != ray.get_runtime_context().get_node_id(), "the fetching actor's node"
    rows = [_byte_row(remote, size) for size in sizes]
    ray.kill(remote)
    return rows


def _byte_row(remote, size: int) -> dict:
    import ray

    array = np.ones(size, np.float32)
    repeats = 5 if size <= 10_000_000 else 2
    put_s = _median_s(lambda: ray.put(array), repeats)
    # A fresh object each time (a node fetches an object once); the put is taken off.
    to_remote_s = _median_s(lambda: ray.get(remote.size_of.remote(ray.put(array))), repeats) - put_s
    from_remote_s = _median_s(lambda: ray.get(remote.zeros.remote(size)), repeats)
    return {"parameters": size, "bytes": 4 * size, "put_s": put_s, "to_other_node_s": max(to_remote_s, 0.0),
            "from_other_node_s": from_remote_s}


def _square_layout(parameters: int, rank: int):
    """A Perturbation of ``parameters`` parameters laid out as a network's are: weight matrices (square, at most
    2,048 wide, the remainder one more matrix of full rows) and a bias under one row (biases keep full noise)."""
    from pizero_ray import es

    side = min(2048, int(np.sqrt(parameters)))
    matrices, rest = divmod(parameters, side * side)
    leaves = ((side, side),) * matrices + (((rest // side, side),) if rest >= side else ())
    leaves += ((rest % side,),) if rest % side else ()
    return es.Perturbation(leaves, rank)


def update_costs(sizes: tuple[int, ...], chunk_size: int, part_ranks: tuple[int, ...] = (0, 1),
                 max_exact_part: int = 10_000_000) -> list[dict]:
    """Per size D: Adam's step over the summed parts (``tell``), the sum's cost per part, and one chunk's part
    regenerated, per rank (rank 0 only up to ``max_exact_part`` parameters: C x D normals to draw)."""
    rows = []
    for size in sizes:
        row = {"parameters": size}
        for rank in part_ranks:
            if rank > 0 or size <= max_exact_part:
                row[f"part_s_rank_{rank}"] = _part_s(size, rank, chunk_size)
        rows.append({**row, **_adam_s(size, chunk_size)})
    return rows


def _strategy(size: int, rank: int, chunk_size: int):
    from pizero_ray import es
    from pizero_ray.config import build_config

    perturbation = _square_layout(size, rank)
    config = build_config("tiny", population=chunk_size, chunk_size=chunk_size, perturbation_rank=rank)
    return es.make_strategy(config, perturbation), perturbation


def _part_s(size: int, rank: int, chunk_size: int) -> float:
    """One chunk's part from regenerated noise, as the driver forms it."""
    strategy, _ = _strategy(size, rank, chunk_size)
    weights = np.linspace(-1, 1, chunk_size).astype(np.float32)
    strategy.parts.regenerated(1, 0, weights)  # compiles
    return _median_s(lambda: strategy.parts.regenerated(2, 0, weights), 3)


def _adam_s(size: int, chunk_size: int) -> dict:
    """``tell`` with one part (the sum's copy, Adam's step), and the cost of adding one more part to the sum."""
    import jax

    strategy, perturbation = _strategy(size, 1, chunk_size)
    state = strategy.init(np.zeros(perturbation.parameter_size, np.float32))
    part = np.zeros(perturbation.parameter_size, np.float32)
    scores, valid = np.zeros((chunk_size, 2), np.float32), np.ones(chunk_size, bool)

    def tell():
        jax.block_until_ready(strategy.tell(state, scores, valid, [part])[0].theta)

    tell()
    total = np.zeros_like(part)
    return {"adam_s": _median_s(tell, 3), "add_part_s": _median_s(lambda: np.add(total, part, out=total), 5)}
