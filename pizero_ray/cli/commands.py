"""The ``pizero`` command: train, resume, eval, inspect, plot.

The thin impure shell: parse and validate everything first (bad input is one
line on stderr, exit code 2, nothing written), then call into the driver.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import signal
import sys
import types
import typing
from pathlib import Path

from pizero_ray.config import Config, ConfigError, build_config
from pizero_ray.presets import PRESETS, method_env_notes
from pizero_ray.settings import Setting, declared
from pizero_ray.storage import run_dir as rundir
from pizero_ray.storage.checkpoints import CheckpointError

DEFAULT_ITERATIONS = 400


class UsageError(Exception):
    pass


def _int_at_least(low: int, description: str):
    """An argparse type: an integer >= low, else an error naming the text given."""

    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = low - 1
        if value < low:
            raise argparse.ArgumentTypeError(f"expected a {description} integer, got {text!r}")
        return value

    return parse


_positive_int = _int_at_least(1, "positive")
_non_negative_int = _int_at_least(0, "non-negative")


def _positive_int_list(text: str) -> tuple[int, ...]:
    """An argparse type: comma-separated positive integers, e.g. 1,10,50."""
    items = text.split(",")
    if not all(item.strip().isdigit() and int(item) > 0 for item in items):
        raise argparse.ArgumentTypeError(f"expected comma-separated positive integers, got {text!r}")
    return tuple(int(item) for item in items)


def _env_arg(text: str) -> tuple[str, object]:
    key, sep, raw = text.partition("=")
    if not sep or not key:
        raise argparse.ArgumentTypeError(f"expected KEY=VALUE, got {text!r}")
    try:
        value = json.loads(raw)
    except json.JSONDecodeError:
        value = raw
    return key, value


_MINIMUM_WORDS = {0: "non-negative", 1: "positive"}


def _comma_list(text: str) -> tuple[str, ...]:
    """An argparse type: comma-separated items, blanks dropped (what they may be is the config's to check)."""
    return tuple(item.strip() for item in text.split(",") if item.strip())


def _argparse_type(s: Setting) -> dict:
    """add_argument's type and action for a declared setting, from its field's type."""
    kind = s.type
    if typing.get_origin(kind) in (typing.Union, types.UnionType):
        (kind,) = [arg for arg in typing.get_args(kind) if arg is not type(None)]
    if kind is bool:  # a flag: --no-X turns a True default off
        return {"action": "store_false" if s.default else "store_true"}
    if typing.get_origin(kind) is tuple:
        item = typing.get_args(kind)[0]
        if typing.get_origin(item) is tuple:  # (key, value) pairs: --flag KEY=VALUE, repeated
            return {"type": _env_arg, "action": "append"}
        return {"type": _comma_list}
    if kind is int and s.minimum is not None:
        return {"type": _int_at_least(s.minimum, _MINIMUM_WORDS.get(s.minimum, f">= {s.minimum}"))}
    return {"type": None if kind is str else kind}


def _help(s: Setting, show_default: bool) -> str:
    text = s.help
    notes = method_env_notes(s.name)  # the per-method, per-environment values, from their one table
    if notes:
        text += f" ({'; '.join(notes)})"
    if s.choices is not None:
        text += f" (one of {', '.join(s.allowed)})"
    if show_default and s.has_default and s.default is not None and s.type is not bool:
        text += f" (default {s.default:g})" if isinstance(s.default, float) else f" (default {s.default})"
    return text.replace("%", "%%")


def _add_settings(parser: argparse.ArgumentParser, cls: type, show_defaults: bool, exclude=()) -> None:
    """One option per declared setting of ``cls`` with a flag (but those named in ``exclude``); its default is
    None, so an absent option leaves the dataclass default (or, for the config, the preset's value) in place."""
    for s in declared(cls):
        if s.flag is not None and s.name not in exclude:
            extra = {"metavar": s.metavar} if s.metavar else {}
            parser.add_argument(s.flag, dest=s.name, default=None, help=_help(s, show_defaults),
                                **_argparse_type(s), **extra)


def _given(cls: type, args) -> dict:
    """The declared settings of ``cls`` given on the command line, by field name."""
    values = {}
    for s in declared(cls):
        value = getattr(args, s.name, None) if s.flag is not None else None
        if value is not None:
            values[s.name] = dict(value) if isinstance(value, list) else value  # KEY=VALUE pairs
    return values


def _add_run_options(parser: argparse.ArgumentParser) -> None:
    """How to run (RunOptions and its PoolOptions); shared by train, chaos and resume."""
    from pizero_ray.trainer.options import RunOptions

    _add_settings(parser, RunOptions, show_defaults=True)
    parser.add_argument("--no-progress", action="store_true", help="print one line per iteration instead of a bar")


def _add_config_options(parser: argparse.ArgumentParser) -> None:
    """What the run computes (the Config); shared by train and chaos. The defaults shown by --help would
    be the 'default' preset's: presets and environments change them, so none is shown."""
    parser.add_argument("--preset", default="default", help=f"one of {', '.join(PRESETS)}")
    _add_settings(parser, Config, show_defaults=False)


def _parser() -> argparse.ArgumentParser:

    parser = argparse.ArgumentParser(prog="pizero", description="PiZero trained by OpenAI-ES on Ray")
    sub = parser.add_subparsers(dest="command", required=True)

    train = sub.add_parser("train", help="train a new run")
    train.add_argument("--run-dir", required=True)
    _add_config_options(train)
    _add_run_options(train)

    chaos = sub.add_parser("chaos", help="train twice, once while killing workers, and compare the parameters")
    chaos.add_argument("--run-dir", required=True, help="gets clean/ and chaos/ run dirs")
    chaos.add_argument("--kills", type=_positive_int, default=3, help="worker processes to SIGKILL (default 3)")
    chaos.add_argument("--chaos-seed", type=_non_negative_int, default=0, help="where the kills fall")
    _add_config_options(chaos)
    _add_run_options(chaos)

    resume = sub.add_parser("resume", help="continue a run from its newest checkpoint")
    resume.add_argument("run_dir")
    resume.add_argument("--restart", action="store_true",
                        help="start again from iteration 0 although the run dir holds progress; what it replaces "
                             "is kept (checkpoints in RUN_DIR/replaced/, metrics rows in metrics-dropped.jsonl)")
    _add_run_options(resume)

    evaluate = sub.add_parser("eval", help="evaluate a run's current parameters")
    evaluate.add_argument("run_dir")
    evaluate.add_argument("--episodes", type=_positive_int, default=1000, help="fresh episodes to play (default 1000)")
    evaluate.add_argument("--seed", type=_non_negative_int, default=0,
                          help="seed of the episodes: the same seed, the same episodes for every run (default 0)")
    evaluate.add_argument("--json", action="store_true", help="print one JSON object")
    evaluate.add_argument("--env-arg", action="append", type=_env_arg, default=[], metavar="KEY=VALUE",
                          help="override an environment parameter (e.g. levels=PATH)")
    evaluate.add_argument("--zero-memory", action="store_true",
                          help="hold the agent's memory at its initial zeros: what the memory is worth (pacman-po)")

    render = sub.add_parser("render", help="draw what a run's agent does (PNG frame or GIF)")
    render.add_argument("run_dir")
    render.add_argument("--episodes", type=_positive_int, default=1, help="episodes to draw (default 1)")
    render.add_argument("--seed", type=_non_negative_int, default=0, help="seed of the episodes (default 0)")
    render.add_argument("--out", required=True, help="FILE.gif (whole episodes) or FILE.png (final frame)")
    render.add_argument("--env-arg", action="append", type=_env_arg, default=[], metavar="KEY=VALUE",
                        help="override an environment parameter (e.g. levels=PATH)")

    inspect = sub.add_parser("inspect", help="iteration and parameter hash of a run")
    inspect.add_argument("run_dir")
    inspect.add_argument("--json", action="store_true", help="print one JSON object")

    bench = sub.add_parser("bench", help="measure rollout, trainer and driver speed (TSP10, paper agent)")
    bench.add_argument("--quick", action="store_true", help="a reduced version (population 64), about a minute")
    bench.add_argument("--json", action="store_true", help="print one JSON object")
    bench.add_argument("--devices", type=_positive_int, metavar="N",
                       help="JAX CPU devices the in-process rollout deals its chunks over (default: one per core)")
    bench.add_argument("--simulations", type=_positive_int_list, metavar="K1,K2,...",
                       help="search budgets to sweep (default 1,10,50; --quick 10)")
    bench.add_argument("--populations", type=_positive_int_list, metavar="P1,P2,...",
                       help="populations (pairs) to sweep (default 64,256,1000; --quick 64)")
    bench.add_argument("--gpus", type=float, default=0.0, metavar="G",
                       help="GPUs the Ray trainer's workers share, G/W each for W workers (default 0: CPU workers)")

    _add_experiment_parsers(sub)

    plot = sub.add_parser("plot", help="learning curves of one or more runs as a PNG")
    plot.add_argument("run_dirs", nargs="+")
    plot.add_argument("--out", required=True)
    plot.add_argument("--labels", help="comma-separated, one per run dir")
    plot.add_argument("--title", default=None)
    return parser


# The experiment's grid axes: every trial gets its own; the other Config settings apply to all trials.
_GRID_FIELDS = ("env", "method", "seed", "env_args")


def _env_scoped_arg(text: str) -> tuple[str, tuple[str, object]]:
    """ENV:KEY=VALUE, an environment parameter for one environment of an experiment."""
    env, sep, pair = text.partition(":")
    if not sep or not env:
        raise argparse.ArgumentTypeError(f"expected ENV:KEY=VALUE, got {text!r}")
    return env, _env_arg(pair)


def _add_experiment_parsers(sub) -> None:
    from pizero_ray.config import METHODS

    experiment = sub.add_parser(
        "experiment", help="train every (env, method, seed) for the same wall-clock budget on Ray Tune; "
                           "run it again to resume an interrupted experiment")
    experiment.add_argument("--envs", type=_comma_list, required=True, help="comma-separated environments")
    experiment.add_argument("--methods", type=_comma_list, default=METHODS,
                            help=f"comma-separated methods (default {','.join(METHODS)})")
    experiment.add_argument("--seeds", type=_positive_int, default=5, help="independent runs each (default 5)")
    experiment.add_argument("--budget-minutes", type=float, required=True,
                            help="training wall-clock per run (evaluations excluded)")
    experiment.add_argument("--eval-every-minutes", type=float, default=None,
                            help="evaluate at every multiple of this on each run's clock (default: budget / 5)")
    experiment.add_argument("--cpus-per-trial", type=_positive_int, default=2,
                            help="CPUs each run holds: ES workers, or a baseline's process (default 2)")
    experiment.add_argument("--out", required=True, help="the experiment's directory (run dirs, Tune's state)")
    experiment.add_argument("--env-arg", dest="env_scoped_args", action="append", type=_env_scoped_arg,
                            default=[], metavar="ENV:KEY=VALUE", help="a parameter of one environment, repeatable")
    experiment.add_argument("--eval-env-arg", dest="eval_env_scoped_args", action="append", type=_env_scoped_arg,
                            default=[], metavar="ENV:KEY=VALUE",
                            help="evaluate that environment with this parameter changed (e.g. sokoban:levels=PATH)")
    experiment.add_argument("--eval-episodes", type=_positive_int, default=256, help="episodes per evaluation")
    experiment.add_argument("--address", default=None, help="Ray cluster address (default: a local instance)")
    experiment.add_argument("--compile-cache", default=None, help="JAX persistent compile cache dir, or 'none'")
    experiment.add_argument("--preset", default="default", help=f"one of {', '.join(PRESETS)}, for every trial")
    _add_settings(experiment, Config, show_defaults=False, exclude=_GRID_FIELDS)

    report = sub.add_parser("plot-experiment", help="an experiment's results figure, table and states figure")
    report.add_argument("experiment_dirs", nargs="+", metavar="EXPERIMENT_DIR",
                        help="an experiment's --out; several: sittings of one experiment over other environments")
    report.add_argument("--out", required=True, help="directory for results.png, results_table.md, results.json")


def _scoped(pairs) -> tuple:
    """[(env, (key, value))] -> ((env, ((key, value), ...)), ...), sorted."""
    by_env: dict[str, dict] = {}
    for env, (key, value) in pairs:
        by_env.setdefault(env, {})[key] = value
    return tuple(sorted((env, tuple(sorted(values.items()))) for env, values in by_env.items()))


def _cmd_experiment(args) -> int:
    from pizero_ray.experiment import grid, runner

    overrides = {name: value for name, value in _given(Config, args).items() if name not in _GRID_FIELDS}
    experiment = grid.Experiment(
        envs=args.envs, methods=args.methods, seeds=args.seeds, budget_minutes=args.budget_minutes,
        eval_every_minutes=args.eval_every_minutes or args.budget_minutes / 5, eval_episodes=args.eval_episodes,
        cpus_per_trial=args.cpus_per_trial, preset=args.preset, overrides=tuple(sorted(overrides.items())),
        env_args=_scoped(args.env_scoped_args), eval_env_args=_scoped(args.eval_env_scoped_args))
    grid.check(experiment)  # every trial's config and environment, before anything starts
    out = rundir.resolve(args.out)
    summary = runner.run(out, experiment, address=args.address, compile_cache=args.compile_cache)
    runner.write_summary(out, summary)
    print(json.dumps(summary))
    missing = [name for name, final in summary["trials"].items() if final is None]
    if missing:
        print(f"pizero: {len(missing)} trials have no result ({', '.join(missing[:4])}...); run the same command "
              "again to resume them", file=sys.stderr)
        return 1
    return 0


def _cmd_plot_experiment(args) -> int:
    from pizero_ray.experiment import grid, report

    sittings = [(out, grid.read_spec(out)) for out in map(rundir.resolve, args.experiment_dirs)]
    summary = report.write_report(sittings, Path(args.out))
    shown = report.state_runs(sittings)
    if shown:
        from pizero_ray.cli.states import states_figure

        eval_env_args = {env: dict(values) for _, spec in sittings for env, values in spec.eval_env_args}
        methods = sorted({report.METHOD_LABELS[path.parent.name] for path in shown.values()})
        title = (f"Seed 0's {' / '.join(methods)} after {sittings[0][1].budget_minutes:g} training minutes: "
                 "one evaluation episode each")
        states_figure(shown, Path(args.out) / "states.png", env_args=eval_env_args,  # Sokoban on its valid levels
                      title=title)
    print(json.dumps({"out": args.out, "results": len(summary["results"]), "states": sorted(shown)}))
    return 0


def _train_config(args):
    config = build_config(args.preset, **_given(Config, args))
    import envs

    try:
        envs.make(config.env, **config.env_kwargs())  # env parameters are checked before anything is written
    except ValueError as error:
        raise UsageError(str(error)) from None
    if config.init_from:  # checked (it is a run dir, its agent fits) before anything is written
        from pizero_ray import methods

        config = dataclasses.replace(config, init_from=str(rundir.resolve(config.init_from)))
        state, layout, _ = methods.initial_state(config, methods.make_env(config))
        methods.warm_start(state, layout, Path(config.init_from))
    return config


def _run_options(args, iterations: int | None, kept: dict | None = None):
    """The run options given, over ``kept`` ones (RunOptions validates them: a bad one is a one-line ConfigError)."""
    from pizero_ray.trainer.options import RunOptions

    # An empty text (--compile-cache '', --address '') means the default, as an absent option does.
    given = {name: value for name, value in _given(RunOptions, args).items() if value != ""}
    return RunOptions.create(**{**(kept or {}), **given, "iterations": iterations})


def _existing_run(path_text: str) -> Path:
    path = rundir.resolve(path_text)
    rundir.read_config(path)  # raises a one-line error naming the path
    return path


def _progress_callbacks(options, no_progress: bool):
    """(on_start, on_iteration, close): a rich progress bar, or plain lines."""
    from rich.console import Console

    console = Console(stderr=True)
    if no_progress or not console.is_terminal:
        def on_start(info):
            print(f"pizero: {info['connection']}, {info['workers']} workers, {info['parameters']} parameters, "
                  f"starting at iteration {info['start_iteration']}", file=sys.stderr, flush=True)

        def on_iteration(row):
            extra = f" eval {row['eval_mean_score']:.4f}" if "eval_mean_score" in row else ""
            total = f"/{options.iterations}" if options.iterations else ""
            print(f"iteration {row['iteration']}{total} mean score {row['mean_score']:.4f}"
                  f"{extra} ({row['iteration_time_s']:.2f} s)", file=sys.stderr, flush=True)

        return on_start, on_iteration, lambda: None

    from rich.progress import (
        BarColumn,
        MofNCompleteColumn,
        Progress,
        TextColumn,
        TimeElapsedColumn,
        TimeRemainingColumn,
    )

    progress = Progress(
        TextColumn("iteration"), MofNCompleteColumn(), BarColumn(),
        TextColumn("score {task.fields[score]}"), TextColumn("{task.fields[rate]} it/s"),
        TimeElapsedColumn(), TextColumn("ETA"), TimeRemainingColumn(), console=console,
    )
    task = None

    def on_start(info):
        nonlocal task
        console.print(f"pizero: {info['connection']}, {info['workers']} workers, {info['parameters']} parameters, "
                      f"starting at iteration {info['start_iteration']}")
        progress.start()
        task = progress.add_task("train", total=options.iterations, completed=info["start_iteration"],
                                 score="-", rate="-")

    def on_iteration(row):
        score = f"{row['mean_score']:.4f}"
        if "eval_mean_score" in row:
            score += f" (eval {row['eval_mean_score']:.4f})"
        progress.update(task, completed=row["iteration"], score=score, rate=f"{1.0 / row['iteration_time_s']:.2f}")

    return on_start, on_iteration, progress.stop


def _run_training(run_path: Path, config, options, no_progress: bool) -> int:
    from pizero_ray.trainer import driver

    on_start, on_iteration, close = _progress_callbacks(options, no_progress)
    try:
        try:
            result = driver.train(run_path, config, options, on_iteration=on_iteration, on_start=on_start)
        finally:
            close()
    except driver.TrainingError as error:  # one line; the run's last checkpoint stands
        print(f"pizero: error: {error}", file=sys.stderr)
        return 1
    print(json.dumps({"run_dir": str(run_path), **result}))
    target = " ".join(f"--{name} {value:g}" for name, value in
                      (("iterations", options.iterations), ("minutes", options.minutes)) if value is not None)
    if result["stopped_by"]:
        print(f"pizero: stopped by {result['stopped_by']} after iteration {result['iteration']}, checkpoint saved; "
              f"continue with: pizero resume {run_path} {target}", file=sys.stderr)
        return 128 + int(getattr(signal, result["stopped_by"]))
    if result["out_of_time"]:
        print(f"pizero: the {options.minutes:g}-minute budget ran out after iteration {result['iteration']}, "
              f"checkpoint saved; give more with: pizero resume {run_path} --minutes M", file=sys.stderr)
    return 0


def _cmd_train(args) -> int:
    config = _train_config(args)
    run_path = rundir.resolve(args.run_dir)
    if (run_path / rundir.CONFIG_FILE).exists():
        raise UsageError(f"run dir {run_path} already holds a run; continue it with: pizero resume {run_path}")
    if run_path.exists() and not run_path.is_dir():
        raise UsageError(f"run dir {run_path} exists and is not a directory")
    # With a wall-clock budget and no iteration target, the budget alone says when to stop.
    iterations = args.iterations or (None if args.minutes else DEFAULT_ITERATIONS)
    options = _run_options(args, iterations)
    rundir.write_config(run_path, config)  # the last steps before training: all input was valid
    rundir.write_evaluation_schedule(run_path, options.evaluation_schedule())
    return _run_training(run_path, config, options, args.no_progress)


def _cmd_chaos(args) -> int:
    """The determinism guarantee, shown: a clean run and one whose workers are SIGKILLed mid-iteration."""
    import numpy as np

    from pizero_ray.trainer import driver

    config = _train_config(args)
    base = rundir.resolve(args.run_dir)
    for name in ("clean", "chaos"):
        if (base / name / rundir.CONFIG_FILE).exists():
            raise UsageError(f"{base / name} already holds a run; choose another --run-dir")
    if args.minutes is not None:
        raise UsageError(f"chaos compares two runs of the same iterations; --minutes {args.minutes:g} would cut "
                         "them at different points")
    options = _run_options(args, args.iterations or 10)
    # Kills fall on random (iteration, chunk) pairs: right after that chunk is handed out,
    # the worker holding it is SIGKILLed (on this machine; a remote worker's actor is killed).
    rng = np.random.default_rng(args.chaos_seed)
    slots = options.iterations * config.num_chunks
    chosen = rng.choice(slots, size=min(args.kills, slots), replace=False)
    schedule = frozenset((int(s) // config.num_chunks, int(s) % config.num_chunks) for s in chosen)
    results = {}
    chaos_options = dataclasses.replace(options, pool=dataclasses.replace(options.pool, kill_schedule=schedule))
    for name, run_options in (("clean", options), ("chaos", chaos_options)):
        path = base / name
        rundir.write_config(path, config)
        print(f"pizero chaos: {name} run in {path}", file=sys.stderr, flush=True)
        results[name] = driver.train(path, config, run_options)
    identical = results["clean"]["parameter_hash"] == results["chaos"]["parameter_hash"]
    print(json.dumps({
        "iterations": options.iterations,
        "workers_killed": results["chaos"]["workers_killed"],
        "clean_parameter_hash": results["clean"]["parameter_hash"],
        "chaos_parameter_hash": results["chaos"]["parameter_hash"],
        "identical": identical,
    }))
    return 0 if identical else 1


def _cmd_resume(args) -> int:
    run_path = _existing_run(args.run_dir)
    config = rundir.read_config(run_path)
    if args.iterations is None and args.minutes is None:
        raise UsageError("resume needs --iterations N (the total number of iterations to reach), "
                         "--minutes M (the run's total wall-clock budget) or both")
    # The learning curve goes on as the run dir says unless an --eval-* option is given.
    kept = rundir.read_evaluation_schedule(run_path)
    options = dataclasses.replace(_run_options(args, args.iterations, kept), restart=args.restart)
    rundir.write_evaluation_schedule(run_path, options.evaluation_schedule())
    return _run_training(run_path, config, options, args.no_progress)


def _print_report(result: dict, as_json: bool, key_width: int) -> None:
    """One JSON object, or one aligned ``key: value`` line per entry."""
    if as_json:
        print(json.dumps(result))
        return
    for key, value in result.items():
        print(f"{key:>{key_width}}: {value}")


def _cmd_eval(args) -> int:
    from pizero_ray.cli.evaluate import evaluate_run

    result = evaluate_run(_existing_run(args.run_dir), args.episodes, args.seed, dict(args.env_arg),
                          zero_memory=args.zero_memory)
    _print_report(result, args.json, key_width=30)
    return 0


def _cmd_inspect(args) -> int:
    from pizero_ray import methods
    from pizero_ray.storage import checkpoints, runs

    run_path = _existing_run(args.run_dir)
    config, iteration, theta, _, _, _ = methods.load_run(run_path)
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
    _print_report(result, args.json, key_width=16)
    return 0


def _cmd_render(args) -> int:
    from pizero_ray.cli import render

    out = Path(args.out)
    if out.suffix.lower() not in (".png", ".gif"):
        raise UsageError(f"--out must end in .png or .gif, got {args.out}")
    frames = render.episode_frames(_existing_run(args.run_dir), args.episodes, args.seed, dict(args.env_arg))
    print(render.write(frames, out))
    return 0


def _cmd_bench(args) -> int:
    from pizero_ray.cli import bench
    from pizero_ray.trainer import local_devices

    local_devices.configure_cpu_devices(args.devices or local_devices.cpu_count())  # before JAX starts
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


def _cmd_plot(args) -> int:
    from pizero_ray.cli.plot import plot_runs

    paths = [_existing_run(p) for p in args.run_dirs]
    labels = args.labels.split(",") if args.labels else [p.name for p in paths]
    if len(labels) != len(paths):
        raise UsageError(f"--labels has {len(labels)} names for {len(paths)} run dirs")
    plot_runs(paths, labels, Path(args.out), args.title)
    print(args.out)
    return 0


COMMANDS = {
    "train": _cmd_train, "resume": _cmd_resume, "eval": _cmd_eval, "inspect": _cmd_inspect,
    "render": _cmd_render, "plot": _cmd_plot, "chaos": _cmd_chaos, "bench": _cmd_bench,
    "experiment": _cmd_experiment, "plot-experiment": _cmd_plot_experiment,
}


def main(argv: list[str] | None = None) -> int:
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    # On a GPU node the driver (or bench, eval) needs a few MB of the GPU; JAX's
    # default of taking 75% of it up front would starve the workers beside it.
    os.environ.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")
    args = _parser().parse_args(argv)
    try:
        return COMMANDS[args.command](args)
    except (ConfigError, UsageError, CheckpointError) as error:
        print(f"pizero: error: {error}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
