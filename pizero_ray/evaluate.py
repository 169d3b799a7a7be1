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


def evaluate_run(run_path: Path, episodes: int, seed: int) -> dict:
    import jax

    import envs
    from pizero_ray import driver, rollout

    config, iteration, theta = driver.load_parameters(run_path)
    env = envs.make(config.env, **config.env_kwargs())
    _, layout = rollout.flat_params(config, env)
    key = jax.random.PRNGKey(seed)
    scores = np.asarray(rollout.make_evaluator(config, env, layout, episodes)(theta, key), dtype=np.float64)
    low, high = confidence_interval95(scores)
    result = {
        "env": config.env,
        "planner": config.planner,
        "iteration": iteration,
        "episodes": episodes,
        "seed": seed,
        "mean_score": float(scores.mean()),
        "std_score": float(scores.std(ddof=1)) if episodes > 1 else 0.0,
        "ci95": [low, high],
    }
    if config.env == "tsp":
        result.update(_tsp_references(env, key, episodes, scores))
    return result


def _tsp_references(env, key, episodes: int, scores: np.ndarray) -> dict:
    """Tour lengths of the same instances under the reference solvers."""
    import jax

    from envs import tsp
    from pizero_ray import rollout

    states, _ = jax.vmap(env.reset)(rollout.episode_reset_keys(key, episodes))
    coordinates = np.asarray(states.coordinates, dtype=np.float64)
    tours = -scores
    out = {
        "mean_tour_length": float(tours.mean()),
        "nearest_neighbour_tour_length": float(tsp.nearest_neighbour_tour_length(coordinates).mean()),
    }
    if coordinates.shape[1] <= tsp.MAX_EXACT_CITIES:
        optimal = tsp.optimal_tour_length(coordinates)
        out["optimal_tour_length"] = float(optimal.mean())
        out["ratio_to_optimal"] = float(tours.mean() / optimal.mean())
        out["mean_optimality_gap"] = float((tours / optimal - 1.0).mean())
    return out
