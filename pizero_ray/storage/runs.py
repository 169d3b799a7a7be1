"""Loading a run to act with it: its config, its newest good checkpoint, its environment.

What eval, render and inspect need, without the Ray trainer.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path
from typing import NamedTuple

import numpy as np

from envs.base import Environment
from pizero_ray.config import Config, ConfigError
from pizero_ray.es.population import FlatParams
from pizero_ray.storage import checkpoints
from pizero_ray.storage import run_dir as rundir


def parameter_hash(theta: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(theta, dtype="<f4").tobytes()).hexdigest()


def initial_state(config: Config, env):
    """A run's ES strategy, its initial state (parameters from config.seed) and the parameters' layout."""
    from pizero_ray import es
    from pizero_ray.es import population

    theta, layout = population.flat_params(config, env)
    strategy = es.make_strategy(config, layout.perturbation)
    return strategy.init(theta), layout, strategy


def restore(run_path: Path, state, **resume_options):
    """``state`` with the run's newest good checkpoint restored into it (see ``checkpoints.prepare_resume``).

    Returns (state, the metrics rows kept). Refuses a run dir whose progress
    it cannot continue; never deletes a metrics row.
    """
    import jax.numpy as jnp

    resumed = checkpoints.prepare_resume(run_path, np.asarray(state.theta), state.opt_state, **resume_options)
    restored = state._replace(theta=jnp.asarray(resumed.theta), opt_state=resumed.opt_state,
                              iteration=resumed.iteration)
    return restored, resumed.metrics


def save(writer, config: Config, state) -> None:
    """Saves ``state`` as the checkpoint of its iteration."""
    theta = np.asarray(state.theta)
    meta = {"iteration": state.iteration, "seed": config.seed, "config": json.loads(config.to_json()),
            "parameter_hash": parameter_hash(theta)}
    writer.save(state.iteration, theta, state.opt_state, meta)


class LoadedRun(NamedTuple):
    config: Config
    iteration: int
    theta: np.ndarray  # flat parameters
    env: Environment
    layout: FlatParams


def load_run(run_path: Path, env_args: dict | None = None) -> LoadedRun:
    """A run dir's newest good checkpoint (or its initial parameters), with its environment.

    ``env_args`` override the run's environment parameters (evaluate on other
    levels, say); they may not change the agent's shape.
    """
    import envs

    config = rundir.read_config(run_path)
    trained_env = envs.make(config.env, **config.env_kwargs())
    state, layout, _ = initial_state(config, trained_env)
    theta, opt_state = np.asarray(state.theta), state.opt_state
    env = trained_env
    if env_args:
        try:
            env = envs.make(config.env, **{**config.env_kwargs(), **env_args})
        except ValueError as error:
            raise ConfigError(str(error)) from None
        # A different horizon is fine (longer games, say); different shapes are not.
        if env.spec._replace(horizon=0) != trained_env.spec._replace(horizon=0):
            raise ConfigError(f"env args {env_args} change the environment's shapes: the trained agent cannot act")
    restored = checkpoints.restore_latest(run_path, theta, opt_state)
    if restored is None:
        return LoadedRun(config, 0, theta, env, layout)
    return LoadedRun(config, restored.iteration, restored.theta, env, layout)
