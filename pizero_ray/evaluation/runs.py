"""Evaluating saved runs: a run's agent on fresh episodes, what its plan is worth, two runs on the same episodes.

Episode i of seed S starts from reset key i of ``episode_reset_keys(PRNGKey(S),
n)``: every run on the same environment plays the same instances for the same
seed, so two runs (or a run and its own ablation) pair episode by episode, and
``paired`` compares them. Runs of any method compare on one environment: two
runs play the same episodes when their environments reset to the same states
for the same keys and end at the same horizon, so parameters that change only
what an agent observes (a view, an encoding) may differ. No Ray: a run is read
through storage.
"""

from __future__ import annotations

import contextlib
import math
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

import numpy as np

from pizero_ray.config import ConfigError

EVAL_SEED = 2_000_003  # the learning curve's fixed held-out episodes (the driver's evaluations, an experiment's)

if TYPE_CHECKING:
    from pizero_ray.config import Config
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


def environment(config: Config) -> str:
    """The run's environment as its command line names it: ``tsp``, ``collect view=centred``."""
    return " ".join([config.env, *(f"{key}={value}" for key, value in sorted(config.env_kwargs().items()))])


def check_same_episodes(run_a: LoadedRun, run_b: LoadedRun, paths: tuple[Path, Path], episodes: int, seed: int) -> None:
    """A one-line error naming both runs unless both environments start every episode from the same state and
    play to the same horizon."""
    import jax
    import numpy as np

    from pizero_ray.agent.episodes import episode_reset_keys

    same = run_a.config.env == run_b.config.env and run_a.env.spec.horizon == run_b.env.spec.horizon
    if same:
        keys = episode_reset_keys(jax.random.PRNGKey(seed), episodes)
        states_a, states_b = (jax.vmap(run.env.reset)(keys)[0] for run in (run_a, run_b))
        leaves_a, tree_a = jax.tree.flatten(states_a)
        leaves_b, tree_b = jax.tree.flatten(states_b)
        same = tree_a == tree_b and all(np.array_equal(a, b) for a, b in zip(leaves_a, leaves_b))
    if not same:
        raise ConfigError(f"{paths[0]} ({environment(run_a.config)}) and {paths[1]} ({environment(run_b.config)}) "
                         "play different episodes: compare runs on the same environment")


class Search(NamedTuple):
    """How one side's agent searches, if not as trained: another budget, or an ablated plan."""

    simulations: int | None = None
    plan: str | None = None


AS_TRAINED = Search()  # the run's own budget, its plan intact


def compare_runs(path_a: Path, path_b: Path, episodes: int, seed: int, trust_env: bool | str = False,
                 search_a: Search = AS_TRAINED, search_b: Search = AS_TRAINED, env_args: dict | None = None,
                 playing=contextlib.nullcontext) -> dict:
    """Both runs' unperturbed agents on the episodes of ``seed``, and their paired comparison; ``trust_env`` as
    for ``methods.load_run``, for both; ``search_a``/``search_b`` change how a side searches (the same run on both
    sides, one ablated: what its plan or its budget is worth); ``env_args`` override both runs' environment
    parameters (Sokoban's valid levels, say); ``playing()`` a context around the playing, once both are loaded."""
    from pizero_ray import methods
    from pizero_ray.evaluation.paired import compare_scores

    if (search_a.plan or search_b.plan) and episodes < 2:
        raise ConfigError("the plan ablation swaps plans between episodes: --episodes must be at least 2")
    run_a, run_b = (methods.with_search(methods.load_run(path, env_args, trust_env), *search)
                    for path, search in ((path_a, search_a), (path_b, search_b)))
    check_same_episodes(run_a, run_b, (path_a, path_b), episodes, seed)
    result = {}
    for name, path, run, search in (("a", path_a, run_a, search_a), ("b", path_b, run_b, search_b)):
        result.update({f"run_{name}": str(path), f"method_{name}": run.config.method,
                       f"planner_{name}": run.config.planner,  # the baselines search with it too
                       f"simulations_{name}": run.config.num_simulations if run.config.planner != "none" else 0,
                       f"plan_{name}": search.plan or "intact",
                       f"env_{name}": environment(run.config),
                       f"iteration_{name}": run.iteration})
    with playing():
        paired = compare_scores(episode_scores(run_a, episodes, seed)[0], episode_scores(run_b, episodes, seed)[0],
                                seed=seed)
    return {**result, "episodes": episodes, "seed": seed, "mean_score_a": paired.mean_a,
            "mean_score_b": paired.mean_b, "mean_difference": paired.mean_difference,
            "ci95": list(paired.interval), "share_a_higher": paired.a_higher, "share_tied": paired.tied,
            "share_b_higher": paired.b_higher}
