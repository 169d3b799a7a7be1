"""`pizero eval`, `inspect`, `render`, `plot` and `bench`: what a saved run does, and how fast the trainer is.

They read run dirs and change none; each loads its heavy modules (JAX, the
figures, the bench) only when it runs.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

from pizero_ray.cli.arguments import (
    UsageError,
    add_env_trust_options,
    env_arg,
    env_trust,
    existing_run,
    non_negative_int,
    positive_int,
    positive_int_list,
)
from pizero_ray.storage import run_dir as rundir


def _add_json_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", action="store_true", help="print one JSON object")


def _add_env_arg_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--env-arg", action="append", type=env_arg, default=[], metavar="KEY=VALUE",
                        help="override an environment parameter (e.g. levels=PATH)")


def add_eval_parser(sub) -> None:
    evaluate = sub.add_parser("eval", help="evaluate a run's current parameters")
    evaluate.add_argument("run_dir")
    evaluate.add_argument("--episodes", type=positive_int, default=1000, help="fresh episodes to play (default 1000)")
    evaluate.add_argument("--seed", type=non_negative_int, default=0,
                          help="seed of the episodes: the same seed, the same episodes for every run (default 0)")
    _add_json_option(evaluate)
    _add_env_arg_option(evaluate)
    evaluate.add_argument("--zero-memory", action="store_true",
                          help="hold the agent's memory at its initial zeros: what the memory is worth (pacman-po)")
    evaluate.add_argument("--per-episode", metavar="FILE",
                          help="also write each episode's score to FILE (replaced if it exists): .jsonl, one JSON "
                               "object a line (episode, seed, score); .npy, the scores alone as float64 in episode "
                               "order. Episode i of --seed S starts from the instance that key i of "
                               "split(fold_in(PRNGKey(S), 0)) resets: the same for every run on the environment; "
                               "the same --seed and --episodes replay the whole evaluation")
    add_env_trust_options(evaluate)
    _add_search_options(evaluate)


def _add_search_options(parser: argparse.ArgumentParser) -> None:
    from pizero_ray.config import PLAN_ABLATIONS

    parser.add_argument("--simulations", type=positive_int, metavar="N",
                        help="search with this budget instead of the run's (a test-time setting; the same parameters)")
    parser.add_argument("--plan", choices=PLAN_ABLATIONS,
                        help="PiZero's plan ablation: the decoder reads another episode's plan (shuffled) or zeros; "
                             "also reports the intact agent on the same episodes, the paired difference, and the "
                             "share of its actions the ablation changes")


def add_render_parser(sub) -> None:
    render = sub.add_parser("render", help="draw what a run's agent does (PNG frame or GIF)")
    render.add_argument("run_dir")
    render.add_argument("--episodes", type=positive_int, default=1, help="episodes to draw (default 1)")
    render.add_argument("--seed", type=non_negative_int, default=0, help="seed of the episodes (default 0)")
    render.add_argument("--out", required=True, help="FILE.gif (whole episodes) or FILE.png (final frame)")
    _add_env_arg_option(render)
    add_env_trust_options(render)


def add_inspect_parser(sub) -> None:
    inspect = sub.add_parser("inspect", help="iteration and parameter hash of a run")
    inspect.add_argument("run_dir")
    _add_json_option(inspect)
    add_env_trust_options(inspect)


def add_bench_parser(sub) -> None:
    bench = sub.add_parser("bench", help="measure rollout, trainer and driver speed (TSP10, paper agent)")
    bench.add_argument("--quick", action="store_true", help="a reduced version (population 64), about a minute")
    bench.add_argument("--scale", action="store_true",
                       help="the trainer at scale instead: the real driver against stub workers (1 to 512), the "
                            "unit costs, and the model built on them (about ten minutes)")
    _add_json_option(bench)
    bench.add_argument("--devices", type=positive_int, metavar="N",
                       help="JAX CPU devices the in-process rollout deals its chunks over (default: one per core)")
    bench.add_argument("--simulations", type=positive_int_list, metavar="K1,K2,...",
                       help="search budgets to sweep (default 1,10,50; --quick 10)")
    bench.add_argument("--populations", type=positive_int_list, metavar="P1,P2,...",
                       help="populations (pairs) to sweep (default 64,256,1000; --quick 64)")
    bench.add_argument("--gpus", type=float, default=0.0, metavar="G",
                       help="GPUs the Ray trainer's workers share, G/W each for W workers (default 0: CPU workers)")


def add_plot_parser(sub) -> None:
    plot = sub.add_parser("plot", help="learning curves of one or more runs as a PNG")
    plot.add_argument("run_dirs", nargs="+")
    plot.add_argument("--out", required=True, help="the PNG to write")
    plot.add_argument("--labels", help="comma-separated, one per run dir (default: the run dirs' names)")
    plot.add_argument("--title", default=None, help="a title above the curves")


# What a learning-curve evaluation writes in its metrics row (trainer.driver._Run.evaluate).
EVALUATION_KEYS = ("eval_mean_score", "eval_plan_shuffled_score", "eval_plan_actions_changed")


def _print_report(result: dict, as_json: bool, key_width: int) -> None:
    """One JSON object, or one aligned ``key: value`` line per entry."""
    if as_json:
        print(json.dumps(result))
        return
    for key, value in result.items():
        print(f"{key:>{key_width}}: {value}")


def cmd_eval(args) -> int:
    from pizero_ray.cli import per_episode
    from pizero_ray.evaluation.runs import evaluate_run_scores

    per_episode_path = per_episode.checked_path(args.per_episode) if args.per_episode else None
    from pizero_ray.cli.progress import stage

    trust = env_trust(args)
    run_path = existing_run(args.run_dir, trust)
    doing = f"playing {args.episodes} episodes" + (f", then again with the plan {args.plan}" if args.plan else "")
    result, scores = evaluate_run_scores(run_path, args.episodes, args.seed, dict(args.env_arg),
                                         zero_memory=args.zero_memory, trust_env=trust, simulations=args.simulations,
                                         plan=args.plan, playing=lambda: stage("pizero eval", doing))
    if per_episode_path is not None:
        result["per_episode"] = str(per_episode.write(per_episode_path, scores, args.seed))
    _print_report(result, args.json, key_width=30)
    return 0


def cmd_inspect(args) -> int:
    from pizero_ray import methods
    from pizero_ray.storage import checkpoints, runs

    trust = env_trust(args)
    run_path = existing_run(args.run_dir, trust)
    config, iteration, theta, _, _, _ = methods.load_run(run_path, trust_env=trust)
    result = {
        "run_dir": str(run_path),
        "env": config.env,
        "method": config.method,
        "iteration": iteration,
        "parameters": int(theta.size),
        "parameter_hash": runs.parameter_hash(theta),
        "checkpoints": checkpoints.checkpoint_steps(run_path),
        "metrics_rows": sum(1 for row in rundir.read_metrics(run_path) if row["iteration"] > 0),
    }
    evaluated = rundir.evaluated_rows(run_path)
    if evaluated:  # the learning curve's last point, with what the plan was worth there (an agent that plans)
        last = evaluated[-1]
        result["last_evaluation"] = {key: last[key] for key in ("iteration", *EVALUATION_KEYS) if key in last}
    _print_report(result, args.json, key_width=16)
    return 0


def cmd_render(args) -> int:
    from pizero_ray.cli import render

    out = Path(args.out)
    if out.suffix.lower() not in (".png", ".gif"):
        raise UsageError(f"--out must end in .png or .gif, got {args.out}")
    from pizero_ray.cli.progress import stage

    trust = env_trust(args)
    run_path = existing_run(args.run_dir, trust)
    doing = f"playing and drawing {args.episodes} episode{'' if args.episodes == 1 else 's'}"
    frames = render.episode_frames(run_path, args.episodes, args.seed, dict(args.env_arg), trust_env=trust,
                                   playing=lambda: stage("pizero render", doing))
    print(render.write(frames, out))
    return 0


def _bench_scale(args) -> int:
    from pizero_ray.bench import scale

    result = scale.run(progress=lambda text: print(f"pizero bench: {text}", file=sys.stderr, flush=True))
    print(json.dumps(result) if args.json else scale.table(result))
    return 0


def cmd_bench(args) -> int:
    from pizero_ray.cli import bench
    from pizero_ray.trainer import chunk_scoring

    if args.scale:
        return _bench_scale(args)

    chunk_scoring.configure_cpu_devices(args.devices or chunk_scoring.cpu_count())  # before JAX starts
    plan = bench.QUICK if args.quick else bench.FULL
    if args.simulations:
        plan = dataclasses.replace(plan, simulation_sweep=args.simulations)
    if args.populations:
        plan = dataclasses.replace(plan, population_sweep=args.populations)
    if args.gpus < 0:
        raise UsageError(f"--gpus must be non-negative, got {args.gpus}")
    result = bench.run(plan, progress=lambda text: print(f"pizero bench: {text}", file=sys.stderr, flush=True),
                       worker_gpus=args.gpus)
    print(bench.to_json(result) if args.json else bench.table(result))
    return 0


def cmd_plot(args) -> int:
    from pizero_ray.cli.plot import plot_runs

    paths = [existing_run(p) for p in args.run_dirs]
    labels = args.labels.split(",") if args.labels else [p.name for p in paths]
    if len(labels) != len(paths):
        raise UsageError(f"--labels has {len(labels)} names for {len(paths)} run dirs")
    plot_runs(paths, labels, Path(args.out), args.title)
    print(args.out)
    return 0
