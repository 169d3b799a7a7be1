"""A run's method, built from its config: its environment, its learner, its initial state, its acting agent.

ES (pizero, es) learns with the ES strategy over ``ESState``; AlphaZero and
MuZero with a baseline ``Learner`` over ``LearnerState``. Both states hold
``theta`` and ``iteration``, and name what else training carries in
``carried`` (``with_carried`` puts it back): checkpoints treat them alike.
``load_run`` builds a saved run's method and restores its newest checkpoint,
for eval, render, inspect and ``--init-from``, without the Ray trainer.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import NamedTuple

import numpy as np

from pizero_ray.config import Config, ConfigError
from pizero_ray.envs.base import Environment
from pizero_ray.es.population import FlatParams
from pizero_ray.storage import checkpoints
from pizero_ray.storage import run_dir as rundir


def make_env(config: Config, **env_args) -> Environment:
    """The environment a run's method acts in: the baselines see continuous actions as a grid
    (pizero_ray.envs.discretised)."""
    from pizero_ray import envs
    from pizero_ray.envs.discretised import discretise

    try:  # a bad parameter, or an environment of your own that cannot be imported or breaks the protocol
        env = envs.make(config.env, **{**config.env_kwargs(), **env_args})
    except ValueError as error:
        raise ConfigError(str(error)) from None
    if config.gradient_trained and not env.spec.discrete:
        env = discretise(env, config.action_grid)
    return env


def initial_state(config: Config, env):
    """(initial state, the parameters' layout, the learner): parameters from config.seed.

    The learner is the ES strategy (pizero, es) or a baseline's ``Learner``
    (alphazero, muzero).
    """
    if config.gradient_trained:
        from pizero_ray.baselines import make_learner

        learner = make_learner(config, env)
        return learner.init(), FlatParams(learner.size, learner.unravel, None), learner
    from pizero_ray import es
    from pizero_ray.es import population

    theta, layout = population.flat_params(config, env)
    strategy = es.make_strategy(config, layout.perturbation)
    return strategy.init(theta), layout, strategy


def other_env(config: Config, trained_env: Environment, env_args: dict | None) -> Environment:
    """The run's environment with ``env_args`` changed (other levels, say), or ``trained_env`` without any.

    A different horizon is fine (longer games); different shapes are not: the trained agent could not act.
    """
    if not env_args:
        return trained_env
    try:
        env = make_env(config, **env_args)
    except ValueError as error:
        raise ConfigError(str(error)) from None
    if env.spec._replace(horizon=0) != trained_env.spec._replace(horizon=0):
        raise ConfigError(f"env args {env_args} change the environment's shapes: the trained agent cannot act")
    return env


def acting_agent(config: Config, env: Environment, learner=None, plan_ablation: str | None = None,
                 watch: str | None = None):
    """The agent that plays a run's episodes (``learner``: initial_state's third value, if at hand).

    ``plan_ablation`` and ``watch``: PiZero's plan ablation (``agent.make_agent``); a baseline has no decoder
    reading a plan, and is refused them in one line."""
    if config.gradient_trained:
        if plan_ablation or watch:
            raise ConfigError(f"the plan ablation is PiZero's (a decoder reading its plan); method {config.method} "
                              "acts on its search's visit counts")
        if learner is None:
            from pizero_ray.baselines import make_learner

            learner = make_learner(config, env)
        return learner.agent
    from pizero_ray.agent import make_agent

    try:
        return make_agent(config, env.spec, plan_ablation, watch)
    except ValueError as error:
        raise ConfigError(str(error)) from None


class LoadedRun(NamedTuple):
    config: Config
    iteration: int
    theta: np.ndarray  # flat parameters
    env: Environment
    layout: FlatParams
    agent: object  # pizero_ray.agent.Agent: what plays the run's episodes


def load_run(run_path: Path, env_args: dict | None = None, trust_env: bool | str = False) -> LoadedRun:
    """A run dir's newest good checkpoint (or its initial parameters), with its environment.

    ``env_args`` override the run's environment parameters (evaluate on other
    levels, say); they may not change the agent's shape. ``trust_env``: an
    environment recorded by import path is imported only if trusted
    (``run_dir.read_trusted_config``): True, or that import path.
    """
    config = rundir.read_trusted_config(run_path, trust_env)
    trained_env = make_env(config)
    state, layout, learner = initial_state(config, trained_env)
    theta = np.asarray(state.theta)
    env = other_env(config, trained_env, env_args)
    agent = acting_agent(config, env, learner if env is trained_env else None)
    restored = checkpoints.restore_latest(run_path, theta, state.carried)
    if restored is None:
        held = checkpoints.held_progress(run_path)
        if held:  # its trained parameters are gone: the untrained agent would stand in for them
            raise checkpoints.CheckpointError(f"run dir {run_path} holds {' and '.join(held)} but no checkpoint: "
                                              "its trained parameters cannot be loaded")
        return LoadedRun(config, 0, theta, env, layout, agent)
    return LoadedRun(config, restored.iteration, restored.theta, env, layout, agent)


def with_search(run: LoadedRun, simulations: int | None = None, plan_ablation: str | None = None,
                watch: str | None = None) -> LoadedRun:
    """``run`` whose agent searches with another budget (``simulations``, a test-time setting, as in AlphaZero
    and MuZero) or whose decoder reads an ablated plan (``agent.make_agent``); the same parameters."""
    config = run.config
    if simulations is not None:
        if config.planner == "none":
            raise ConfigError(f"run {config.method} on {config.env} has no planner: --simulations does not apply")
        config = dataclasses.replace(config, num_simulations=simulations).validate()
    if config == run.config and plan_ablation is None and watch is None:
        return run
    return run._replace(config=config, agent=acting_agent(config, run.env, None, plan_ablation, watch))


def warm_start(state, layout: FlatParams, source: Path, trust_env: bool | str = False):
    """``state`` (a fresh run's) with its parameters replaced by run dir ``source``'s newest (``--init-from``).

    The optimiser state and iteration stay fresh. Raises ConfigError, one line, if ``source`` is not a run dir
    or its parameters do not fit ``layout``. ``trust_env`` as for ``load_run``: the new run's own environment,
    which the user named, is the one import path worth trusting.
    """
    import jax
    import jax.numpy as jnp

    loaded = load_run(source, trust_env=trust_env)
    shapes = jax.tree.map(np.shape, layout.unravel(jnp.asarray(state.theta)))
    if jax.tree.map(np.shape, loaded.layout.unravel(loaded.theta)) != shapes:  # the same shapes: the same size
        raise ConfigError(f"--init-from {source}: its agent ({loaded.config.method} on {loaded.config.env}, "
                          f"{loaded.theta.size} parameters) does not fit this run's ({layout.size} parameters)")
    return state._replace(theta=jnp.asarray(loaded.theta, jnp.float32))
