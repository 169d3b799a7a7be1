"""The bytes an iteration moves between the driver and its workers, as the trainer's pool counts them.

The pool counts the actual objects as they go (``trainer.pool.Traffic``): the
parameters once per worker node, each chunk's call and scores, and each
gradient part's weights and part where parts are asked of workers (with
``--gradient-on`` resolved to the driver none are). The driver writes the
counts to every metrics row (``bytes_to_workers``, ``bytes_from_workers``);
the bench reports their medians over the iterations of its trainer runs.
"""

from __future__ import annotations

import statistics

from pizero_ray.config import Config
from pizero_ray.trainer.options import PoolOptions


def median_traffic(rows: list[dict]) -> dict:
    """Median bytes per iteration each way over the metrics ``rows`` of a run."""
    return {key: statistics.median(row[key] for row in rows) for key in ("bytes_to_workers", "bytes_from_workers")}


def where_gradient_parts_form(config: Config, options: PoolOptions) -> str:
    """Where the run's gradient parts were formed (``--gradient-on`` resolved): "driver" or "workers"."""
    return "driver" if options.gradient_on_driver(config.perturbation_rank) else "workers"
