"""The project's population rollout, timed in this process as a worker runs it: chunk by chunk, over devices."""

from __future__ import annotations

import time

import numpy as np

from pizero_ray.bench.timing import CompiledRollout, time_interleaved
from pizero_ray.config import Config


def compile_rollout(config: Config, max_devices: int | None = None) -> CompiledRollout:
    """The rollout a worker runs (``chunk_scoring.ChunkScorer``), compiled for this process's devices (or the
    first ``max_devices``), its chunks dealt over them."""
    from pizero_ray import envs
    from pizero_ray.es import population
    from pizero_ray.trainer import chunk_scoring

    env = envs.make(config.env, **config.env_kwargs())
    theta = np.asarray(population.flat_params(config, env)[0])
    started = time.perf_counter()
    chunks = chunk_scoring.ChunkScorer(config, max_devices)
    chunks.wait_until_compiled()
    compile_s = time.perf_counter() - started  # every device's program
    first_pairs = range(0, config.population, config.chunk_size)

    def one_iteration(seed: int) -> float:
        started = time.perf_counter()
        chunks.score_all(theta, seed, first_pairs)  # returns once every chunk's scores are on the host
        return time.perf_counter() - started

    one_iteration(0)  # warm-up
    # Counted to the horizon: every TSP episode runs to it (on a game that ends early, this would count steps
    # the rollout, which stops once all of a chunk's episodes have ended, never plays).
    agent_steps = config.population * 2 * config.episodes_per_member * env.spec.horizon
    return CompiledRollout(config, one_iteration, compile_s, chunks.parameters, agent_steps, chunks.num_devices)


def rollouts(configs: dict[str, Config], repeats: int, max_devices: dict[str, int] | None = None) -> dict[str, dict]:
    """The rollout of each config alone, in this process, timed interleaved (``timing.time_interleaved``).

    Chunks are dealt over all local devices unless ``max_devices`` limits a config.
    """
    limits = max_devices or {}
    return time_interleaved({name: compile_rollout(config, limits.get(name)) for name, config in configs.items()},
                            repeats)


def rollout(config: Config, repeats: int) -> dict:
    """The rollout of one config alone (see ``rollouts``)."""
    return rollouts({"rollout": config}, repeats)["rollout"]


def pair_scorer_loops(config: Config) -> dict:
    """``loops.summary`` of the chunk program the workers run (``population.make_pair_scorer``), compiled for
    this process's first device: its while loops, how they nest, which are data-dependent.

    Lowered as ``chunk_scoring.ChunkScorer`` lowers it (each input placed on the device), so that with a
    persistent compile cache the scorer's program is loaded, not compiled again."""
    import jax
    import jax.numpy as jnp
    from jax.sharding import SingleDeviceSharding

    from pizero_ray import envs
    from pizero_ray.bench import loops
    from pizero_ray.es import population

    env = envs.make(config.env, **config.env_kwargs())
    layout = population.params_layout(config, env)
    chunk, on = config.chunk_size, SingleDeviceSharding(jax.local_devices()[0])
    text = population.make_pair_scorer(config, env, layout).lower(
        jax.ShapeDtypeStruct((layout.size,), jnp.float32, sharding=on),
        jax.ShapeDtypeStruct((), jnp.uint32, sharding=on), jax.ShapeDtypeStruct((chunk,), jnp.int32, sharding=on),
        jax.ShapeDtypeStruct((chunk, layout.perturbation.noise_size), jnp.float32, sharding=on),
    ).compile().as_text()
    return loops.summary(text)
