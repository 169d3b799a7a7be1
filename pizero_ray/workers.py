"""Ray worker actors: each holds the compiled population rollout and evaluates chunks."""

from __future__ import annotations

import os
import time

import numpy as np
import ray


class RolloutWorker:
    """Evaluates chunks of antithetic pairs; returns their scores [C, 2] as float32."""

    def __init__(self, config_json: str, compile_cache_dir: str | None):
        from pizero_ray import compile_cache

        compile_cache.enable(compile_cache_dir)
        import jax
        import jax.numpy as jnp

        import envs
        from pizero_ray import rollout
        from pizero_ray.config import Config

        self._started = time.time()
        self._jnp = jnp
        self.config = Config.from_json(config_json)
        env = envs.make(self.config.env, **self.config.env_kwargs())
        _, layout = rollout.flat_params(self.config, env)
        self._evaluate = rollout.make_pair_evaluator(self.config, env, layout)
        self._device = str(jax.devices()[0])
        self._chunks_done = 0

    def evaluate_chunk(self, theta: np.ndarray, iteration_seed: int, first_pair: int) -> np.ndarray:
        jnp = self._jnp
        pairs = jnp.arange(first_pair, first_pair + self.config.chunk_size, dtype=jnp.int32)
        scores = self._evaluate(jnp.asarray(theta), np.uint32(iteration_seed), pairs)
        self._chunks_done += 1
        return np.asarray(scores, dtype=np.float32)

    def info(self) -> dict:
        return {
            "pid": os.getpid(),
            "node_id": ray.get_runtime_context().get_node_id(),
            "device": self._device,
            "chunks_done": self._chunks_done,
            "uptime_s": time.time() - self._started,
        }


def start_worker(config_json: str, num_cpus: float, num_gpus: float, compile_cache_dir: str | None):
    env_vars = {"RAY_USAGE_STATS_ENABLED": "0"}
    if num_gpus == 0:
        env_vars["JAX_PLATFORMS"] = "cpu"  # a CPU worker on a GPU node must not grab the GPU
    actor = ray.remote(RolloutWorker).options(
        num_cpus=num_cpus, num_gpus=num_gpus, runtime_env={"env_vars": env_vars}, max_concurrency=1
    )
    return actor.remote(config_json, compile_cache_dir)
