"""Evaluating the unperturbed agent of a run dir on fresh episodes."""

from __future__ import annotations

import contextlib
import math
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from pizero_ray.config import ConfigError

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
                 zero_memory: bool = False, trust_env: bool | str = False, simulations: int | None = None,
                 plan: str | None = None) -> dict:
    """The unperturbed agent on fresh episodes (``evaluate_run_scores``'s report)."""
    return evaluate_run_scores(run_path, episodes, seed, env_args, zero_memory, trust_env, simulations, plan)[0]


def evaluate_run_scores(run_path: Path, episodes: int, seed: int, env_args: dict | None = None,
                        zero_memory: bool = False, trust_env: bool | str = False, simulations: int | None = None,
                        plan: str | None = None, playing=contextlib.nullcontext) -> tuple[dict, np.ndarray]:
    """The unperturbed agent on fresh episodes, and the scores it summarises in episode order (``episode_scores``).

    ``env_args`` override the run's (e.g. other levels); ``zero_memory`` holds the agent's memory at its initial
    zeros (``agent.without_memory``); ``trust_env`` as for ``methods.load_run``; ``simulations`` searches with
    that budget; ``plan`` (``agent.PLAN_ABLATIONS``) has the decoder read an ablated plan, and the report then
    says what that costs the same agent on the same episodes (``plan_ablation``). ``playing()``: a context
    around the episodes played, once the run is loaded (the CLI's progress lines).
    """
    import jax

    from pizero_ray import methods
    from pizero_ray.agent import episodes as play
    from pizero_ray.agent import without_memory

    run = methods.with_search(methods.load_run(run_path, env_args, trust_env), simulations)
    if plan is not None and episodes < 2:
        raise ConfigError(f"the plan ablation swaps plans between episodes: --episodes must be at least 2, "
                          f"got {episodes}")
    intact = run
    if plan is not None:
        run = methods.with_search(run, plan_ablation=plan)
    if zero_memory:
        run, intact = (r._replace(agent=without_memory(r.agent)) for r in (run, intact))
    with playing():
        scores, final_states = episode_scores(run, episodes, seed)
        result = _report(run, episodes, seed, scores)
        if plan is not None:
            result.update(plan=plan, **plan_ablation(intact, plan, episodes, seed, scores))
    if simulations is not None:
        result["simulations"] = simulations
    if zero_memory:
        result["memory"] = "zeroed"
    env = run.env
    if env.episode_metrics is not None:
        for name, values in env.episode_metrics(final_states).items():
            result[f"mean_{name}"] = float(np.mean(values))
    if env.references is not None:
        initial_states, _ = jax.vmap(env.reset)(play.episode_reset_keys(jax.random.PRNGKey(seed), episodes))
        result.update(env.references(initial_states, scores))
    return result, scores


def _report(run: LoadedRun, episodes: int, seed: int, scores: np.ndarray) -> dict:
    low, high = confidence_interval95(scores)
    return {"env": run.config.env, "method": run.config.method, "planner": run.config.planner,
            "iteration": run.iteration, "episodes": episodes, "seed": seed, "mean_score": float(scores.mean()),
            "std_score": float(scores.std(ddof=1)) if episodes > 1 else 0.0, "ci95": [low, high]}


def plan_ablation(intact: LoadedRun, ablation: str, episodes: int, seed: int, ablated_scores: np.ndarray) -> dict:
    """What the plan is worth to ``intact``'s agent: its own score on the same episodes, the paired difference
    (ablated minus intact) with its 95% BCa interval, the share of episodes whose score did not change, and the
    share of its actions the ablated plan would have changed along its own episodes."""
    import jax

    from pizero_ray import methods
    from pizero_ray.agent import episodes as play
    from pizero_ray.evaluation.paired import compare_scores

    watching = methods.with_search(intact, watch=ablation)
    scorer = play.make_plan_use_scorer(watching.agent, watching.env, watching.layout.unravel, episodes)
    intact_scores, changed = scorer(intact.theta, jax.random.PRNGKey(seed))
    paired = compare_scores(ablated_scores, np.asarray(intact_scores, np.float64), seed=seed)
    return {"intact_mean_score": paired.mean_b, "plan_difference": paired.mean_difference,
            "plan_difference_ci95": list(paired.interval), "share_episodes_unchanged": paired.tied,
            "share_actions_changed": float(changed)}
