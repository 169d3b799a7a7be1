"""The driver's update made entirely in the driver: every chunk's noise regenerated, the gradient, Adam."""

from __future__ import annotations

import statistics
import time

import numpy as np

from pizero_ray.config import Config


def driver_update(config: Config, repeats: int) -> float:
    """Median seconds of one such update.

    That is the driver's fallback (and, with ``--gradient-on driver``, its
    way); by default the workers return the parts from the noise they kept
    (the trainer's ``update_s``).
    """
    import jax

    from pizero_ray import envs, es
    from pizero_ray.es import population

    env = envs.make(config.env)
    theta, layout = population.flat_params(config, env)
    strategy = es.make_strategy(config, layout.perturbation)
    state = strategy.init(theta)
    scores = np.random.default_rng(0).normal(size=(config.population, 2)).astype(np.float32)
    valid = np.ones((config.population,), bool)

    def update(seed: int):
        weights = strategy.weights(scores, valid)
        parts = [strategy.parts.chunk_here(seed, weights, index) for index in range(config.num_chunks)]
        return strategy.tell(state, scores, valid, parts)[0]

    jax.block_until_ready(update(0))  # the compile
    times = []
    for seed in range(repeats):
        started = time.perf_counter()
        jax.block_until_ready(update(seed))
        times.append(time.perf_counter() - started)
    return statistics.median(times)
