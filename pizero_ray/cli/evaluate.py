"""Evaluating the unperturbed agent of a run dir on fresh episodes."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np


def confidence_interval95(values: np.ndarray) -> tuple[float, float]:
    mean = float(values.mean())
    if values.size < 2:
        return mean, mean
    half = 1.96 * float(values.std(ddof=1)) / math.sqrt(values.size)
    return mean - half, mean + half


def evaluate_run(run_path: Path, episodes: int, seed: int, env_args: dict | None = None,
                 zero_memory: bool = False) -> dict:
    """The unperturbed agent on fresh episodes; ``env_args`` override the run's (e.g. other levels);
    ``zero_memory`` holds the agent's memory at its initial zeros (``agent.without_memory``)."""
    import jax

    from pizero_ray import methods
    from pizero_ray.agent import episodes as play
    from pizero_ray.agent import without_memory

    config, iteration, theta, env, layout, agent = methods.load_run(run_path, env_args)
    if zero_memory:
        agent = without_memory(agent)
    key = jax.random.PRNGKey(seed)
    evaluator = play.make_scorer(agent, env, layout.unravel, episodes, final_states=True)
    scores, final_states = evaluator(theta, key)
    scores = np.asarray(scores, dtype=np.float64)
    low, high = confidence_interval95(scores)
    result = {
        "env": config.env,
        "method": config.method,
        "planner": config.planner,
        "iteration": iteration,
        "episodes": episodes,
        "seed": seed,
        "mean_score": float(scores.mean()),
        "std_score": float(scores.std(ddof=1)) if episodes > 1 else 0.0,
        "ci95": [low, high],
    }
    if zero_memory:
        result["memory"] = "zeroed"
    if env.episode_metrics is not None:
        for name, values in env.episode_metrics(final_states).items():
            result[f"mean_{name}"] = float(np.mean(values))
    if env.references is not None:
        initial_states, _ = jax.vmap(env.reset)(play.episode_reset_keys(key, episodes))
        result.update(env.references(initial_states, scores))
    return result
