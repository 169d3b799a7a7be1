"""pizero-ray as a library: train and resume runs, evaluate and compare them, act with a trained agent.

Every function here is what a ``pizero`` command does, without the command
line: the CLI parses its options and calls these. A run dir is the unit, as
for the CLI: ``train`` writes one, the others read it. Settings are the
``Config`` fields (what is computed: ``env``, ``population``, ``planner``...)
and the ``RunOptions``/``PoolOptions`` fields (how it runs: ``iterations``,
``minutes``, ``workers``...), given by field name; docs/options.md lists them.
Bad input raises ``ConfigError`` (a ValueError) with one line naming it,
before anything is written.
"""

from __future__ import annotations

import dataclasses
import functools
from pathlib import Path
from typing import Any, Callable

import numpy as np

from pizero_ray.config import Config, ConfigError, build_config
from pizero_ray.storage import run_dir as rundir
from pizero_ray.storage import writer_lock

DEFAULT_ITERATIONS = 400  # where neither iterations nor minutes is given
_CONFIG_FIELDS = {f.name for f in dataclasses.fields(Config)}


def new_run_config(preset: str = "default", **settings: Any) -> Config:
    """The config of a new run (``settings`` over ``preset``), its environment built and its warm start
    (``init_from``) checked: a bad one is a one-line ConfigError."""
    from pizero_ray import methods

    config = build_config(preset, **settings)
    env = methods.make_env(config)  # the environment's parameters, and an environment of your own, are checked
    if config.init_from:
        config = dataclasses.replace(config, init_from=str(rundir.resolve(config.init_from)))
        state, layout, _ = methods.initial_state(config, env)
        methods.warm_start(state, layout, Path(config.init_from), trust_env=config.env)
    return config


def check_new_run(run_path: Path, config: Config, options) -> None:
    """Everything a new run is refused for, before anything is written: a run dir that holds a run (or what is
    left of one) or cannot be written, options that do not fit the config, a config that cannot fit in memory."""
    from pizero_ray import footprint, methods
    from pizero_ray.storage import checkpoints

    rundir.check_location(run_path)
    if (run_path / rundir.CONFIG_FILE).exists():
        raise ConfigError(f"run dir {run_path} already holds a run; continue it with: pizero resume {run_path}")
    held = checkpoints.held_progress(run_path) if run_path.is_dir() else []
    if held:  # a run whose config.json is gone: a new config would silently continue its checkpoints
        raise ConfigError(f"run dir {run_path} holds {' and '.join(held)} but no {rundir.CONFIG_FILE}: it is not "
                          "a new run dir; put its config.json back and resume it, or choose another run dir")
    options.pool.check_against(config)
    footprint.check_fits(config, methods.make_env(config), options.eval_episodes)


def start_run(run_path: Path, config: Config, options, on_start: Callable | None = None,
              on_iteration: Callable | None = None) -> dict:
    """Writes a new run dir and trains it (``driver.train``'s result); ``check_new_run`` first, and again once
    the run dir is locked (another process may have got there first)."""
    from pizero_ray.trainer import driver

    check_new_run(run_path, config, options)
    with writer_lock.hold(run_path):  # one writer per run dir, from its first file on
        check_new_run(run_path, config, options)
        rundir.write_config(run_path, config)
        rundir.write_schedule(run_path, options.schedule())
        return driver.train(run_path, config, options, on_iteration=on_iteration, on_start=on_start)


def continue_run(run_path: Path, config: Config, options, on_start: Callable | None = None,
                 on_iteration: Callable | None = None) -> dict:
    """Trains a run dir on from its newest checkpoint (``driver.train``'s result): refused, before anything is
    written, if its config.json differs from what its checkpoints were trained with."""
    from pizero_ray.storage import runs
    from pizero_ray.trainer import driver

    rundir.check_location(run_path)
    options.pool.check_against(config)
    if not options.restart:
        runs.check_same_config(run_path, config)

    def started(info: dict) -> None:
        # The schedule is written once the run has started (its checkpoint restored, its config agreed): a
        # refused resume leaves the run dir as it found it.
        rundir.write_schedule(run_path, options.schedule())
        if on_start is not None:
            on_start(info)

    with writer_lock.hold(run_path):
        return driver.train(run_path, config, options, on_iteration=on_iteration, on_start=started)


def _run_options(values: dict, kept: dict | None = None):
    from pizero_ray.trainer.options import RunOptions

    return RunOptions.create(**{**(kept or {}), **values})


def train(run_dir: str | Path, *, preset: str = "default", on_iteration: Callable[[dict], None] | None = None,
          **settings: Any) -> dict:
    """Trains a new run in ``run_dir``; returns {"iteration", "parameter_hash", "stopped_by", "out_of_time", ...}.

    ``settings``: Config and RunOptions fields by name (``env="collect"``, ``minutes=10``, ``workers=2``);
    without ``iterations`` or ``minutes``, 400 iterations. ``on_iteration(row)`` gets each iteration's metrics
    row as it is written to metrics.jsonl.
    """
    config = new_run_config(preset, **{k: v for k, v in settings.items() if k in _CONFIG_FIELDS})
    values = {k: v for k, v in settings.items() if k not in _CONFIG_FIELDS}
    if values.get("iterations") is None and values.get("minutes") is None:
        values["iterations"] = DEFAULT_ITERATIONS
    return start_run(rundir.resolve(run_dir), config, _run_options(values), on_iteration=on_iteration)


def resume(run_dir: str | Path, *, on_iteration: Callable[[dict], None] | None = None,
           trust_env: bool | str = False, restart: bool = False, **options: Any) -> dict:
    """Trains ``run_dir`` on to ``iterations`` in all, or ``minutes`` of training in all; the run's schedule
    (evaluations, checkpoints) goes on unless given. ``trust_env``: see ``run_dir.read_trusted_config``."""
    run_path = rundir.resolve(run_dir)
    config = rundir.read_trusted_config(run_path, trust_env)
    run_options = dataclasses.replace(_run_options(options, rundir.read_schedule(run_path)), restart=restart)
    return continue_run(run_path, config, run_options, on_iteration=on_iteration)


def evaluate(run_dir: str | Path, episodes: int = 1000, seed: int = 0, **options: Any) -> dict:
    """The run's agent on ``episodes`` fresh episodes of ``seed`` (what ``pizero eval --json`` prints).
    ``options``: env_args, zero_memory, trust_env, simulations, plan ("shuffled" or "zeroed")."""
    from pizero_ray.evaluation.runs import evaluate_run

    return evaluate_run(rundir.resolve(run_dir), episodes, seed, **options)


def compare(run_a: str | Path, run_b: str | Path, episodes: int = 1000, seed: int = 0, **options: Any) -> dict:
    """Two runs' agents on the same episodes, compared episode by episode (what ``pizero compare --json``
    prints). ``options``: trust_env, search_a/search_b (``Search(simulations, plan)``), env_args."""
    from pizero_ray.evaluation.runs import compare_runs

    return compare_runs(rundir.resolve(run_a), rundir.resolve(run_b), episodes, seed, **options)


@dataclasses.dataclass(frozen=True)
class TrainedAgent:
    """A run's agent with its newest parameters, to act in a loop of your own: ``initial_memory(batch)``, then
    each step ``act(observation, memory, key) -> (action, memory)`` on a batch of the environment's
    observations (``env.reset``/``env.step`` under ``jax.vmap``)."""

    config: Config
    env: Any  # pizero_ray.envs.base.Environment
    iteration: int
    params: Any  # the agent's parameter pytree
    agent: Any  # pizero_ray.agent.Agent, or a baseline's

    def initial_memory(self, batch: int = 1):
        return self.agent.initial_memory(batch)

    def act(self, observation, memory, key, env_state=None):
        """(actions [batch], new memory): the agent's choice for each observation; AlphaZero also needs the
        environment's states (``env_state``), which it searches from."""
        action, memory, _ = self._act(self.params, memory, observation, key, env_state)
        return action, memory

    @functools.cached_property
    def _act(self):
        import jax

        return jax.jit(self.agent.act)


def load_agent(run_dir: str | Path, env_args: dict | None = None, trust_env: bool | str = False) -> TrainedAgent:
    """A run's trained agent (its newest checkpoint) and its environment; ``env_args`` change parameters that
    keep the agent's shapes (Sokoban's levels, a longer horizon)."""
    from pizero_ray import methods

    run = methods.load_run(rundir.resolve(run_dir), env_args, trust_env)
    return TrainedAgent(run.config, run.env, run.iteration, run.layout.unravel(np.asarray(run.theta)), run.agent)
