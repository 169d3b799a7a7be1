"""`pizero compare`: two runs' agents on the same episodes, compared episode by episode
(``pizero_ray.evaluation.runs.compare_runs``), and its report."""

from __future__ import annotations

import json

from pizero_ray.cli.arguments import (
    add_env_trust_options,
    env_arg,
    env_trust,
    existing_run,
    int_at_least,
    non_negative_int,
)

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
    from pizero_ray.evaluation.runs import Search, compare_runs

    result = compare_runs(path_a, path_b, args.episodes, args.seed, trust,
                          Search(args.simulations_a, args.plan_a), Search(args.simulations_b, args.plan_b),
                          dict(args.env_arg),
                          playing=lambda: stage("pizero compare", f"playing {args.episodes} episodes with each agent"))
    print(json.dumps(result) if args.json else text_report(result))
    return 0
