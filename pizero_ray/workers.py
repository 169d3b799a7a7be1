"""Ray worker actors: each holds the compiled population rollout and evaluates chunks.

A worker compiles its rollout ahead of time in ``__init__`` (a hit in JAX's
persistent compilation cache when another worker compiled the same program
before), so "ready" means "can return a chunk in one rollout's time", and the
driver's per-chunk timeout need not allow for compiles.
"""

from __future__ import annotations

import os
import resource
import time

import numpy as np
import ray


class RolloutWorker:
    """Evaluates chunks of antithetic pairs; returns their scores [C, 2] as float32."""

    def __init__(self, config_json: str, compile_cache_dir: str | None):
        started = time.time()
        from pizero_ray import compile_cache

        compile_cache.enable(compile_cache_dir)
        import jax
        import jax.numpy as jnp

        import envs
        from pizero_ray import rollout
        from pizero_ray.config import Config

        self.config = Config.from_json(config_json)
        env = envs.make(self.config.env, **self.config.env_kwargs())
        theta, layout = rollout.flat_params(self.config, env)
        pairs = jnp.arange(self.config.chunk_size, dtype=jnp.int32)
        evaluate = rollout.make_pair_evaluator(self.config, env, layout)
        self._evaluate = evaluate.lower(theta, np.uint32(0), pairs).compile()
        self._jnp = jnp
        self._info = {
            "pid": os.getpid(),
            "node_id": ray.get_runtime_context().get_node_id(),
            "device": str(jax.devices()[0]),
            "startup_s": time.time() - started,
        }

    def ready(self) -> dict:
        return self._info

    def peak_rss_mb(self) -> float:
        """This worker process's peak resident memory (for `pizero bench`)."""
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0

    def evaluate_chunk(self, theta: np.ndarray, iteration_seed: int, first_pair: int) -> np.ndarray:
        jnp = self._jnp
        pairs = jnp.arange(first_pair, first_pair + self.config.chunk_size, dtype=jnp.int32)
        scores = self._evaluate(jnp.asarray(theta, jnp.float32), np.uint32(iteration_seed), pairs)
        return np.asarray(scores, dtype=np.float32)


def start_worker(
    config_json: str, num_cpus: float, num_gpus: float, compile_cache_dir: str | None, resources: dict | None = None
):
    env_vars = {"RAY_USAGE_STATS_ENABLED": "0"}
    if num_gpus == 0:
        env_vars["JAX_PLATFORMS"] = "cpu"  # a CPU worker on a GPU node must not grab the GPU
    actor = ray.remote(RolloutWorker).options(
        num_cpus=num_cpus, num_gpus=num_gpus, resources=resources or {}, runtime_env={"env_vars": env_vars},
        max_concurrency=1,
    )
    return actor.remote(config_json, compile_cache_dir)
