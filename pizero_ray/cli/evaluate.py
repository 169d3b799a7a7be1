"""Evaluating the unperturbed agent of a run dir on fresh episodes."""

from __future__ import annotations

import math
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from pizero_ray.methods import LoadedRun


def confidence_interval95(values: np.ndarray) -> tuple[float, float]:
    mean = float(values.mean())
    if values.size < 2:
        return mean, mean
    half = 1.96 * float(values.std(ddof=1)) / math.sqrt(values.size)
    return mean - half, mean + half


def episode_scores(run: LoadedRun, episodes: int, seed: int) -> tuple[np.ndarray, object]:
    """(scores [episodes], float64 in episode order; final states) of a loaded run's unperturbed agent.

    Episode i starts from reset key i of ``episode_reset_keys(PRNGKey(seed), episodes)``: every run on the
    same environment plays the same instances for the same seed (``pizero compare`` pairs them by it).
    """
    import jax

    from pizero_ray.agent import episodes as play

    scorer = play.make_scorer(run.agent, run.env, run.layout.unravel, episodes, final_states=True)
    scores, final_states = scorer(run.theta, jax.random.PRNGKey(seed))
    return np.asarray(scores, dtype=np.float64), final_states


def evaluate_run(run_path: Path, episodes: int, seed: int, env_args: dict | None = None,
                 zero_memory: bool = False, trust_env: bool | str = False) -> dict:
    """The unperturbed agent on fresh episodes; ``env_args`` override the run's (e.g. other levels);
    ``zero_memory`` holds the agent's memory at its initial zeros (``agent.without_memory``); ``trust_env``
    as for ``methods.load_run``."""
    return evaluate_run_scores(run_path, episodes, seed, env_args, zero_memory, trust_env)[0]


def evaluate_run_scores(run_path: Path, episodes: int, seed: int, env_args: dict | None = None,
                        zero_memory: bool = False, trust_env: bool | str = False) -> tuple[dict, np.ndarray]:
    """``evaluate_run``'s report, and the scores it summarises in episode order (``episode_scores``)."""
    import jax

    from pizero_ray import methods
    from pizero_ray.agent import episodes as play
    from pizero_ray.agent import without_memory

    run = methods.load_run(run_path, env_args, trust_env)
    config, iteration, env = run.config, run.iteration, run.env
    if zero_memory:
        run = run._replace(agent=without_memory(run.agent))
    scores, final_states = episode_scores(run, episodes, seed)
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
        initial_states, _ = jax.vmap(env.reset)(play.episode_reset_keys(jax.random.PRNGKey(seed), episodes))
        result.update(env.references(initial_states, scores))
    return result, scores
