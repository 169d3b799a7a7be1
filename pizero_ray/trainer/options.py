"""How a run is run (not what it computes): the run's and the worker pool's options.

Each option's default, flag and help are declared once, in its field
(pizero_ray.settings); the command line is generated from them. None of this
changes the parameters, except ``min_fraction`` < 1. Pure dataclasses: no Ray.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from typing import Any

from pizero_ray.config import Config, ConfigError
from pizero_ray.settings import check_minimums, lookup, setting
from pizero_ray.trainer import compile_cache

# The run's schedule, the learning curve's and the checkpoints': a run dir keeps it (evaluation.json) and a
# resume goes on with it unless given other values.
SCHEDULE_FIELDS = ("eval_every", "eval_every_minutes", "eval_episodes", "eval_env_args", "checkpoint_every",
                   "keep_checkpoints")


def _flag(cls: type, name: str) -> str:
    return lookup(cls, name).flag


# Where each chunk's share of the pseudo-gradient is formed. "workers": by the worker that evaluated the chunk,
# from the noise it kept (a second round trip per iteration); "driver": the driver regenerates every chunk's
# noise (no round trip; cheap when the noise is low rank). "auto": the driver for low-rank noise on CPU
# workers, else the workers (docs/performance.md has the measurements behind it).
GRADIENT_ON = ("auto", "workers", "driver")


@dataclass(frozen=True)
class PoolOptions:
    """The worker pool: how many actors, their resources, and how long a chunk may take."""

    workers: int = setting(2, flag="--workers", minimum=1, help="worker actors")
    max_workers: int | None = setting(
        None, flag="--max-workers", minimum=1,
        help="start more actors, up to this many, as the cluster grows (default: --workers)")
    min_fraction: float = setting(
        1.0, flag="--min-fraction",
        help="finish an iteration once this fraction of chunks is in, dropping stragglers "
             "(faster, no longer deterministic; 1: complete)")
    chunk_timeout_s: float = setting(
        300.0, flag="--chunk-timeout", metavar="SECONDS", help="seconds before a worker holding a chunk counts as hung")
    cpus_per_worker: float = setting(
        1.0, flag="--cpus-per-worker", minimum=0,
        help="CPUs per worker; a CPU worker runs a JAX CPU device on each")
    gpus_per_worker: float = setting(0.0, flag="--gpus-per-worker", minimum=0, help="GPUs per worker (0: CPU workers)")
    pin_cores: bool = setting(
        True, flag="--no-pin-cores",
        help="leave CPU workers unpinned (default: each pins itself to cores no other worker holds)")
    compile_cache: str | None = setting(
        str(compile_cache.DEFAULT_DIR), flag="--compile-cache",
        help="JAX persistent compile cache dir, or 'none'")
    gradient_on: str = setting(
        "auto", flag="--gradient-on", choices=GRADIENT_ON,
        help="where each chunk's share of the update is formed: 'workers' (from the noise they kept), 'driver' "
             "(it regenerates the noise; no second round trip), 'auto' (driver for low-rank noise on CPU "
             "workers, else workers); on CPU workers the parameters are the same either way")
    chunks_per_call: int = setting(
        1, flag="--chunks-per-call", minimum=1,
        help="chunks a worker is handed in one call: fewer calls for the driver when an iteration has thousands "
             "(each chunk is still scored alone: the parameters are the same); a multiple of "
             "--chunks-per-launch, or 1 for one launch a call")
    worker_wait_minutes: float = setting(
        15.0, flag="--worker-wait-minutes",
        help="how long the run waits with no live worker (at start-up, or after losing them all) for the "
             "cluster to supply one before it stops: long enough for a spot cluster to replace its nodes")
    in_flight_per_worker: int = 2  # per device: keeps a worker busy while its last result travels
    worker_resources: tuple[tuple[str, float], ...] = ()  # custom Ray resources each worker needs
    # Chaos: (iteration, chunk) pairs; right after that chunk is handed out, its worker's process is SIGKILLed.
    kill_schedule: frozenset[tuple[int, int]] = frozenset()

    def __post_init__(self) -> None:
        self.validate()

    @property
    def target_workers(self) -> int:
        """The actors the pool keeps asking Ray for: ``max_workers``, and never fewer than ``workers``."""
        return max(self.workers, self.max_workers or 0)

    def gradient_on_driver(self, perturbation_rank: int) -> bool:
        """Whether the driver forms every chunk's gradient part itself (``gradient_on`` resolved)."""
        if self.gradient_on == "auto":
            return perturbation_rank > 0 and self.gpus_per_worker == 0
        return self.gradient_on == "driver"

    def validate(self) -> "PoolOptions":
        """Raises ConfigError, one line naming the value, on an option out of range."""
        check_minimums(self, ConfigError)
        if self.gradient_on not in GRADIENT_ON:
            raise ConfigError(f"{_flag(PoolOptions, 'gradient_on')} must be one of {', '.join(GRADIENT_ON)}, "
                              f"got {self.gradient_on!r}")
        if not 0 < self.min_fraction <= 1:
            raise ConfigError(f"{_flag(PoolOptions, 'min_fraction')} must be in (0, 1], got {self.min_fraction}")
        for name in ("chunk_timeout_s", "worker_wait_minutes"):
            if getattr(self, name) <= 0:
                raise ConfigError(f"{_flag(PoolOptions, name)} must be positive, got {getattr(self, name)}")
        if self.max_workers is not None and self.max_workers < self.workers:
            raise ConfigError(f"{_flag(PoolOptions, 'max_workers')} {self.max_workers} is below "
                              f"{_flag(PoolOptions, 'workers')} {self.workers}")
        return self

    def check_against(self, config: Config) -> "PoolOptions":
        """Raises ConfigError, one line naming both values, on an option that does not fit the ``Config``.

        A call carries whole launches (``config.chunks_per_launch`` chunks, run
        as one device call): a launch split across two calls would run on two
        workers, each computing all of it. 1, the default, is a launch a call.
        """
        per_call, per_launch = self.chunks_per_call, config.chunks_per_launch
        if per_call != 1 and per_call % per_launch != 0:
            raise ConfigError(f"{_flag(PoolOptions, 'chunks_per_call')} {per_call} is not a multiple of "
                              f"{_flag(Config, 'chunks_per_launch')} {per_launch}")
        return self


@dataclass(frozen=True)
class RunOptions:
    """A run: how far, on which cluster, checkpoints, evaluation; and its worker pool's options."""

    iterations: int | None = setting(
        None, flag="--iterations", minimum=1,
        help="total iterations to reach (train: 400 if neither this nor --minutes is given; with --minutes "
             "alone, as many as the budget allows)")
    minutes: float | None = setting(
        None, flag="--minutes",
        help="stop, with a checkpoint, once the run has trained this many wall-clock minutes in all "
             "(its metrics' wall_time_s, which carries on across resumes)")
    pool: PoolOptions = field(default_factory=PoolOptions)
    address: str | None = setting(
        None, flag="--address", help="Ray cluster address (default: RAY_ADDRESS, else a local instance)")
    checkpoint_every: int = setting(25, flag="--checkpoint-every", minimum=0,
                                    help="iterations between periodic checkpoints (0: none)")
    keep_checkpoints: int = setting(3, flag="--keep-checkpoints", minimum=1, help="newest checkpoints kept")
    eval_every: int = setting(0, flag="--eval-every", minimum=0,
                              help="evaluate the unperturbed agent every K iterations (0: never)")
    eval_every_minutes: float | None = setting(
        None, flag="--eval-every-minutes",
        help="also evaluate each time the training wall-clock passes a multiple of this many minutes "
             "(learning curves at equal time points, whatever an iteration costs)")
    eval_episodes: int = setting(256, flag="--eval-episodes", minimum=1, help="episodes per evaluation")
    eval_env_args: tuple[tuple[str, Any], ...] = setting(
        (), flag="--eval-env-arg", metavar="KEY=VALUE",
        help="evaluate the learning curve on the environment with this parameter changed (repeatable), "
             "e.g. levels=PATH: train on one level set, report on another")
    restart: bool = False  # start over at iteration 0 though the run dir holds progress (checkpoints.prepare_resume)

    def __post_init__(self) -> None:
        self.validate()

    def validate(self) -> "RunOptions":
        """Raises ConfigError, one line naming the value, on an option out of range (the pool's too)."""
        check_minimums(self, ConfigError)
        if self.iterations is None and self.minutes is None:
            raise ConfigError("give --iterations N (the total to reach), --minutes M (a wall-clock budget) or both")
        if self.minutes is not None and not self.minutes > 0:
            raise ConfigError(f"--minutes must be positive, got {self.minutes}")
        if self.eval_every_minutes is not None and not self.eval_every_minutes > 0:
            raise ConfigError(f"--eval-every-minutes must be positive, got {self.eval_every_minutes}")
        self.pool.validate()
        return self

    def schedule(self) -> dict:
        """The evaluation and checkpoint settings by field name (what a resume keeps unless told otherwise)."""
        return {name: getattr(self, name) for name in SCHEDULE_FIELDS}

    @classmethod
    def create(cls, **values: Any) -> "RunOptions":
        """RunOptions from the fields of RunOptions and of its PoolOptions, given by name side by side."""
        pool_fields = {f.name for f in dataclasses.fields(PoolOptions)}
        unknown = set(values) - pool_fields - {f.name for f in dataclasses.fields(cls)}
        if unknown:
            raise TypeError(f"RunOptions has no option {', '.join(sorted(unknown))}")
        if isinstance(values.get("eval_env_args"), (dict, list)):  # KEY=VALUE pairs: command line or JSON
            values["eval_env_args"] = tuple(sorted(dict(values["eval_env_args"]).items()))
        pool = PoolOptions(**{k: v for k, v in values.items() if k in pool_fields})
        return cls(pool=pool, **{k: v for k, v in values.items() if k not in pool_fields})
