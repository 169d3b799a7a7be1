"""The scale model: an iteration's time at W workers, K chunks and D parameters, from measured unit costs.

Pure arithmetic over what ``scale`` and ``scale_costs`` measured (``UnitCosts``);
nothing here runs Ray or JAX. An iteration is

    iteration_s = max(compute_s, chunks x driver_per_chunk_s) + update_s + broadcast_s

- ``compute_s``: the rollout, population x steps per pair / (workers x rate),
  the work that would take all of the time if the driver were free;
- handing out and collecting chunks overlaps the rollout until the driver,
  at ``driver_per_chunk_s`` a chunk (measured against stub workers), is the
  slower of the two;
- the update and the parameters' broadcast happen between rollouts.

Designs:
- ``a_parts_on_driver`` (today's, rank-1 noise on CPU workers): the driver
  regenerates every chunk's part (``part_s`` each), sums them, takes Adam's
  step, puts theta (D floats) and each node fetches it;
- ``a_parts_on_workers`` (today's, full-rank or GPU workers): each chunk's
  part, D floats, comes back to the driver and is added there;
- ``a_node_sums`` (not built): as ``a_parts_on_workers``, but each node adds
  its workers' parts first, so one part a node comes back, not one a chunk;
- ``b_replayed`` (OpenAI-ES's, not built): every worker keeps theta and Adam's
  state and replays the update from the seed and the scores; only the scores
  go out (population x 8 bytes to each node). Each worker then regenerates
  every chunk's part itself, so the update is ``chunks x part_s`` on every
  worker, not once on the driver, and nothing of size D moves.
The network is the measured node-to-node rate (this machine's loopback
between two Ray nodes) unless another is given; the driver's node sends
theta to every node in turn (the worst case: Ray may fetch from any node
that holds a copy).
"""

from __future__ import annotations

import math
from typing import NamedTuple

GPUS_PER_NODE = 8
STEPS_PER_PAIR = 20  # two members, one TSP10 episode each


class UnitCosts(NamedTuple):
    driver_per_chunk_s: float  # handing out and collecting one chunk, measured against stub workers
    bytes_per_s: float  # between two nodes
    put_bytes_per_s: float  # into the driver's object store
    part_s: dict  # D -> a part regenerated on the driver, seconds per pair of its chunk (it grows with the pairs)
    adam_s: dict  # D -> Adam's step
    add_part_s: dict  # D -> adding one part to the sum


def _at(table: dict, parameters: int) -> float:
    """A per-D cost at ``parameters``: measured there, else linear in D from the largest measured below or above."""
    if parameters in table:
        return table[parameters]
    known = sorted(table)
    nearest = max([d for d in known if d <= parameters], default=known[0])
    return table[nearest] * parameters / nearest


def iteration(costs: UnitCosts, design: str, workers: int, chunks: int, pairs_per_chunk: int, parameters: int,
              rate_per_worker: float) -> dict:
    """One modelled iteration: its parts in seconds and bytes, and the efficiency (compute over total)."""
    nodes = max(1, math.ceil(workers / GPUS_PER_NODE))
    compute_s = chunks * pairs_per_chunk * STEPS_PER_PAIR / (workers * rate_per_worker)
    scheduling_s = chunks * costs.driver_per_chunk_s
    theta_bytes, scores_bytes = 4 * parameters, 8 * chunks * pairs_per_chunk
    if design == "a_node_sums":  # not built: each node adds its workers' parts, one sum per node comes back
        update_s = nodes * (theta_bytes / costs.bytes_per_s + _at(costs.add_part_s, parameters))
        update_s += _at(costs.adam_s, parameters)
        to_workers, to_driver = nodes * theta_bytes, scores_bytes + nodes * theta_bytes
        broadcast_s = theta_bytes / costs.put_bytes_per_s + nodes * theta_bytes / costs.bytes_per_s
    elif design == "b_replayed":
        # on every worker, at once
        update_s = chunks * pairs_per_chunk * _at(costs.part_s, parameters) + _at(costs.adam_s, parameters)
        to_workers, to_driver = nodes * scores_bytes, scores_bytes
        broadcast_s = to_workers / costs.bytes_per_s
    else:
        parts_back = design == "a_parts_on_workers"
        per_part = (theta_bytes / costs.bytes_per_s + _at(costs.add_part_s, parameters) if parts_back
                    else pairs_per_chunk * _at(costs.part_s, parameters) + _at(costs.add_part_s, parameters))
        update_s = chunks * per_part + _at(costs.adam_s, parameters)
        to_workers, to_driver = nodes * theta_bytes, scores_bytes + (chunks * theta_bytes if parts_back else 0)
        broadcast_s = theta_bytes / costs.put_bytes_per_s + nodes * theta_bytes / costs.bytes_per_s
    iteration_s = max(compute_s, scheduling_s) + update_s + broadcast_s
    return {"design": design, "workers": workers, "chunks": chunks, "pairs_per_chunk": pairs_per_chunk,
            "update_s": update_s, "broadcast_s": broadcast_s,
            "parameters": parameters, "source": "model",
            "compute_s": compute_s, "driver_s": scheduling_s + (0.0 if design == "b_replayed" else update_s),
            "iteration_s": iteration_s, "bytes_to_workers": int(to_workers), "bytes_to_driver": int(to_driver),
            "efficiency": compute_s / iteration_s}


def saturation_workers(costs: UnitCosts, pairs_per_chunk: int, rate_per_worker: float) -> float:
    """The worker count at which the driver's chunk handling takes as long as the rollout it feeds.

    A worker eats a chunk every pairs x steps / rate seconds; the driver hands
    out one every ``driver_per_chunk_s``: whatever the population, more workers
    than this wait on the driver. Only bigger chunks (or several per call) move it.
    """
    return pairs_per_chunk * STEPS_PER_PAIR / (rate_per_worker * costs.driver_per_chunk_s)


def replay_speedup_to_beat(costs: UnitCosts, other: str, workers: int, chunks: int, pairs_per_chunk: int,
                           parameters: int, rate_per_worker: float) -> float:
    """How many times faster than this machine's driver a worker would have to replay the update (GPU workers
    would: not measured here) for replayed updates to take less time an iteration than ``other``."""
    replayed = iteration(costs, "b_replayed", workers, chunks, pairs_per_chunk, parameters, rate_per_worker)
    rival = iteration(costs, other, workers, chunks, pairs_per_chunk, parameters, rate_per_worker)
    margin = rival["update_s"] + rival["broadcast_s"] - replayed["broadcast_s"]
    return replayed["update_s"] / margin if margin > 0 else float("inf")
