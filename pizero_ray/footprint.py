"""What a configuration needs in memory, estimated from shapes alone, so that one that cannot fit is refused
before anything is written or allocated.

The estimate is a floor, not a forecast: the arrays a run cannot do without
(the parameters and the optimiser's copies of them on the driver, one
launch's episodes and perturbed parameters on a worker, the driver's
per-iteration bookkeeping of every pair and chunk). A configuration whose
floor exceeds the machine's memory would grow until the kernel's
out-of-memory killer ended it, taking other processes with it. Shapes come
from ``jax.eval_shape``: nothing is computed or allocated here.
"""

from __future__ import annotations

import os
from typing import NamedTuple

import numpy as np

from pizero_ray.config import Config, ConfigError

FLOAT_BYTES = 4
DRIVER_PARAMETER_COPIES = 6  # theta, Adam's two moments, the pseudo-gradient, its parts' sum, the update
DRIVER_BYTES_PER_PAIR = 32  # scores [2], weights [2] and validity, as float32 and bool, with numpy's slack
DRIVER_BYTES_PER_CHUNK = 400  # the queue's Python objects: an index, its entries in a deque and three dicts
EPISODE_COPIES = 2  # an episode's state and observation, as carried and as the step returns them


class Footprint(NamedTuple):
    parameters: int  # the agent's parameter count
    driver_bytes: int
    launch_bytes: int  # one worker launch (a chunk, or chunks_per_launch of them), or the evaluation's episodes


def _tree_bytes(tree) -> int:
    import jax

    return int(sum(np.prod(leaf.shape, dtype=np.int64) * np.dtype(leaf.dtype).itemsize
                   for leaf in jax.tree.leaves(tree)))


def estimate(config: Config, env, eval_episodes: int = 0) -> Footprint:
    """The memory floor of training ``config`` on ``env`` (``methods.make_env``'s), from shapes alone."""
    import jax
    import jax.numpy as jnp

    key = jax.ShapeDtypeStruct((2,), jnp.uint32)
    if config.gradient_trained:
        from pizero_ray.baselines.search import make_method_search

        init_params, _ = make_method_search(config, env, training=True)
        parameters = _tree_bytes(jax.eval_shape(init_params, key)) // FLOAT_BYTES
    else:
        from pizero_ray.es.population import params_layout

        parameters = params_layout(config, env).size
    episode_bytes = _tree_bytes(jax.eval_shape(env.reset, key))
    members = 2 * config.chunk_size * config.chunks_per_launch
    episodes = max(members * config.episodes_per_member, eval_episodes)
    if config.gradient_trained:
        members, episodes = 1, max(config.selfplay_episodes, eval_episodes)
    perturbed = members * parameters * FLOAT_BYTES if config.perturbation_rank == 0 else 0
    launch = episodes * episode_bytes * EPISODE_COPIES + perturbed + parameters * FLOAT_BYTES
    driver = (parameters * FLOAT_BYTES * DRIVER_PARAMETER_COPIES + config.population * DRIVER_BYTES_PER_PAIR
              + config.num_chunks * DRIVER_BYTES_PER_CHUNK)
    return Footprint(parameters, driver, launch)


def machine_bytes() -> int:
    """This machine's physical memory."""
    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")


def _gib(count: int) -> str:
    return f"{count / 2**30:,.1f} GiB"


def check_fits(config: Config, env, eval_episodes: int = 0, available: int | None = None) -> Footprint:
    """The footprint, or a one-line ConfigError naming what does not fit in ``available`` bytes (this machine's
    memory by default: the driver's, and a worker's when it runs here)."""
    available = machine_bytes() if available is None else available
    found = estimate(config, env, eval_episodes)
    if found.driver_bytes > available:
        raise ConfigError(f"{found.parameters:,} parameters and a population of {config.population:,} pairs need at "
                          f"least {_gib(found.driver_bytes)} on the driver, more than this machine's "
                          f"{_gib(available)}")
    if found.launch_bytes > available:
        raise ConfigError(f"environment {config.env} {dict(config.env_args) or ''}".rstrip() +
                          f" with chunks of {config.chunk_size} pairs and {found.parameters:,} parameters needs at "
                          f"least {_gib(found.launch_bytes)} for one launch of episodes, more than this machine's "
                          f"{_gib(available)}")
    return found
