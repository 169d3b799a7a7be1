"""`pizero compare`: two runs' agents on the same episodes, compared episode by episode.

Both agents play the episodes of one seed (the same reset keys: the same
instances), as ``pizero eval`` plays them; the statistics are
``pizero_ray.evaluation.paired``'s. Runs of any method compare, on one
environment: two runs play the same episodes when their environments reset to
the same states for the same keys and end at the same horizon, so parameters
that change only what an agent observes (a view, an encoding) may differ.
"""

from __future__ import annotations

import contextlib
import json
from pathlib import Path
from typing import TYPE_CHECKING, NamedTuple

from pizero_ray.cli.arguments import (
    UsageError,
    add_env_trust_options,
    env_arg,
    env_trust,
    existing_run,
    int_at_least,
    non_negative_int,
)

if TYPE_CHECKING:
    from pizero_ray.config import Config
    from pizero_ray.methods import LoadedRun

at_least_two = int_at_least(2, ">= 2")  # one episode has no spread to bootstrap


def add_compare_parser(sub) -> None:
    compare = sub.add_parser("compare", help="play two runs' agents on the same episodes and compare them pairwise")
    compare.add_argument("run_a")
    compare.add_argument("run_b")
    compare.add_argument("--episodes", type=at_least_two, default=1000,
                         help="episodes both agents play (default 1000)")
    compare.add_argument("--seed", type=non_negative_int, default=0,
                         help="seed of the episodes, as pizero eval's, and of the bootstrap (default 0)")
    compare.add_argument("--json", action="store_true", help="print one JSON object")
    add_env_trust_options(compare)
    compare.add_argument("--env-arg", action="append", type=env_arg, default=[], metavar="KEY=VALUE",
                         help="play both on the environment with this parameter changed (e.g. levels=PATH)")
    from pizero_ray.config import PLAN_ABLATIONS

    for side in ("a", "b"):
        compare.add_argument(f"--simulations-{side}", type=int_at_least(1, "positive"), metavar="N",
                             help=f"run {side.upper()} searches with this budget (a test-time setting)")
        compare.add_argument(f"--plan-{side}", choices=PLAN_ABLATIONS,
                             help=f"run {side.upper()}'s decoder reads another episode's plan (shuffled) or zeros: "
                                  "pair a run against its own plan ablation by naming it twice")


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
        raise UsageError(f"{paths[0]} ({environment(run_a.config)}) and {paths[1]} ({environment(run_b.config)}) "
                         "play different episodes: compare runs on the same environment")


class Search(NamedTuple):
    """How one side's agent searches, if not as trained: another budget, or an ablated plan."""

    simulations: int | None = None
    plan: str | None = None


def compare_runs(path_a: Path, path_b: Path, episodes: int, seed: int, trust_env: bool | str = False,
                 search_a: Search = Search(), search_b: Search = Search(), env_args: dict | None = None,
                 playing=contextlib.nullcontext) -> dict:
    """Both runs' unperturbed agents on the episodes of ``seed``, and their paired comparison; ``trust_env`` as
    for ``methods.load_run``, for both; ``search_a``/``search_b`` change how a side searches (the same run on both
    sides, one ablated: what its plan or its budget is worth); ``env_args`` override both runs' environment
    parameters (Sokoban's valid levels, say); ``playing()`` a context around the playing, once both are loaded."""
    from pizero_ray import methods
    from pizero_ray.cli.evaluate import episode_scores
    from pizero_ray.evaluation.paired import compare_scores

    if (search_a.plan or search_b.plan) and episodes < 2:
        raise UsageError("the plan ablation swaps plans between episodes: --episodes must be at least 2")
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


# How a baseline's search is named: AlphaZero and MuZero search with mctx's MuZero policy (PUCT) or Gumbel.
_BASELINE_SEARCH = {"muzero": "PUCT search", "gumbel": "Gumbel search"}


def agent_label(method: str, planner: str, simulations: int, plan: str = "intact") -> str:
    """The agent as a person reads it: "pizero, planner muzero with 10 simulations", "alphazero, PUCT search with
    32 simulations"; "es, no planner"."""
    if planner == "none":
        label = f"{method}, no planner"
    else:
        search = _BASELINE_SEARCH[planner] if method in ("alphazero", "muzero") else f"planner {planner}"
        label = f"{method}, {search} with {simulations} simulation{'' if simulations == 1 else 's'}"
    return label if plan == "intact" else f"{label}, plan {plan}"


def text_report(result: dict) -> str:
    """What ``compare_runs`` found, in a few lines; every score with 4 decimals."""
    low, high = result["ci95"]
    lines = []
    for name in ("a", "b"):
        agent = agent_label(result[f"method_{name}"], result[f"planner_{name}"], result[f"simulations_{name}"],
                            result[f"plan_{name}"])
        lines.append(f"run {name.upper()}: {result[f'run_{name}']} ({agent}, {result[f'env_{name}']}, "
                     f"iteration {result[f'iteration_{name}']})")
    return "\n".join([
        *lines,
        f"episodes: {result['episodes']} (seed {result['seed']}), the same for both",
        f"mean score A: {result['mean_score_a']:.4f}",
        f"mean score B: {result['mean_score_b']:.4f}",
        f"mean A - B: {result['mean_difference']:+.4f}, 95% BCa interval [{low:+.4f}, {high:+.4f}]",
        f"A higher on {result['share_a_higher']:.1%} of episodes, tied on {result['share_tied']:.1%}, "
        f"B higher on {result['share_b_higher']:.1%}",
    ])


def cmd_compare(args) -> int:
    trust = env_trust(args)
    path_a, path_b = existing_run(args.run_a, trust), existing_run(args.run_b, trust)
    from pizero_ray.cli.progress import stage

    result = compare_runs(path_a, path_b, args.episodes, args.seed, trust,
                          Search(args.simulations_a, args.plan_a), Search(args.simulations_b, args.plan_b),
                          dict(args.env_arg),
                          playing=lambda: stage("pizero compare", f"playing {args.episodes} episodes with each agent"))
    print(json.dumps(result) if args.json else text_report(result))
    return 0
