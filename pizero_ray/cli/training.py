"""`pizero train`, `resume` and `chaos`: check every input, write the run dir, then hand over to the driver."""

from __future__ import annotations

import argparse
import dataclasses
import json
import signal
import sys
from pathlib import Path

from pizero_ray.cli.arguments import UsageError, add_settings, existing_run, given, non_negative_int, positive_int
from pizero_ray.config import Config, build_config
from pizero_ray.presets import PRESETS
from pizero_ray.storage import run_dir as rundir
from pizero_ray.storage import writer_lock

DEFAULT_ITERATIONS = 400


def _add_run_options(parser: argparse.ArgumentParser) -> None:
    """How to run (RunOptions and its PoolOptions); shared by train, chaos and resume."""
    from pizero_ray.trainer.options import RunOptions

    add_settings(parser, RunOptions, show_defaults=True)
    parser.add_argument("--no-progress", action="store_true", help="print one line per iteration instead of a bar")


def _add_config_options(parser: argparse.ArgumentParser) -> None:
    """What the run computes (the Config); shared by train and chaos. The defaults shown by --help would
    be the 'default' preset's: presets and environments change them, so none is shown."""
    parser.add_argument("--preset", default="default", help=f"one of {', '.join(PRESETS)}")
    add_settings(parser, Config, show_defaults=False)


def add_train_parser(sub) -> None:
    train = sub.add_parser("train", help="train a new run")
    train.add_argument("--run-dir", required=True)
    _add_config_options(train)
    _add_run_options(train)


def add_chaos_parser(sub) -> None:
    chaos = sub.add_parser("chaos", help="train twice, once while killing workers, and compare the parameters")
    chaos.add_argument("--run-dir", required=True, help="gets clean/ and chaos/ run dirs")
    chaos.add_argument("--kills", type=positive_int, default=3, help="worker processes to SIGKILL (default 3)")
    chaos.add_argument("--chaos-seed", type=non_negative_int, default=0, help="where the kills fall")
    _add_config_options(chaos)
    _add_run_options(chaos)


def add_resume_parser(sub) -> None:
    resume = sub.add_parser("resume", help="continue a run from its newest checkpoint")
    resume.add_argument("run_dir")
    resume.add_argument("--restart", action="store_true",
                        help="start again from iteration 0 although the run dir holds progress; what it replaces "
                             "is kept (checkpoints in RUN_DIR/replaced/, metrics rows in metrics-dropped.jsonl)")
    _add_run_options(resume)


def train_config(args) -> Config:
    """The config given (over its preset), its environment parameters and warm start checked."""
    config = build_config(args.preset, **given(Config, args))
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


def run_options(args, iterations: int | None, kept: dict | None = None):
    """The run options given, over ``kept`` ones (RunOptions validates them: a bad one is a one-line ConfigError)."""
    from pizero_ray.trainer.options import RunOptions

    # An empty text (--compile-cache '', --address '') means the default, as an absent option does.
    values = {name: value for name, value in given(RunOptions, args).items() if value != ""}
    return RunOptions.create(**{**(kept or {}), **values, "iterations": iterations})


def _run_training(run_path: Path, config: Config, options, no_progress: bool) -> int:
    from pizero_ray.cli.progress import progress_callbacks
    from pizero_ray.trainer import driver

    on_start, on_iteration, close = progress_callbacks(options, no_progress)
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


def _refuse_a_run_dir_with_a_run(run_path: Path) -> None:
    if (run_path / rundir.CONFIG_FILE).exists():
        raise UsageError(f"run dir {run_path} already holds a run; continue it with: pizero resume {run_path}")


def cmd_train(args) -> int:
    config = train_config(args)
    run_path = rundir.resolve(args.run_dir)
    _refuse_a_run_dir_with_a_run(run_path)
    if run_path.exists() and not run_path.is_dir():
        raise UsageError(f"run dir {run_path} exists and is not a directory")
    # With a wall-clock budget and no iteration target, the budget alone says when to stop.
    iterations = args.iterations or (None if args.minutes else DEFAULT_ITERATIONS)
    options = run_options(args, iterations)
    with writer_lock.hold(run_path):  # one writer per run dir, from its first file on
        _refuse_a_run_dir_with_a_run(run_path)  # again: another `pizero train` may have got there first
        rundir.write_config(run_path, config)  # the last steps before training: all input was valid
        rundir.write_evaluation_schedule(run_path, options.evaluation_schedule())
        return _run_training(run_path, config, options, args.no_progress)


def cmd_resume(args) -> int:
    run_path = existing_run(args.run_dir)
    config = rundir.read_config(run_path)
    if args.iterations is None and args.minutes is None:
        raise UsageError("resume needs --iterations N (the total number of iterations to reach), "
                         "--minutes M (the run's total wall-clock budget) or both")
    # The learning curve goes on as the run dir says unless an --eval-* option is given.
    kept = rundir.read_evaluation_schedule(run_path)
    options = dataclasses.replace(run_options(args, args.iterations, kept), restart=args.restart)
    with writer_lock.hold(run_path):  # refused, before writing anything, while another process trains the run
        rundir.write_evaluation_schedule(run_path, options.evaluation_schedule())
        return _run_training(run_path, config, options, args.no_progress)


def cmd_chaos(args) -> int:
    """The determinism guarantee, shown: exit code 0 if the clean and the chaos run end with the same parameters."""
    from pizero_ray.trainer import chaos

    config = train_config(args)
    base = rundir.resolve(args.run_dir)
    for name in chaos.RUN_NAMES:
        if (base / name / rundir.CONFIG_FILE).exists():
            raise UsageError(f"{base / name} already holds a run; choose another --run-dir")
    if args.minutes is not None:
        raise UsageError(f"chaos compares two runs of the same iterations; --minutes {args.minutes:g} would cut "
                         "them at different points")
    options = run_options(args, args.iterations or 10)
    report = chaos.compare_runs(
        base, config, options, kills=args.kills, seed=args.chaos_seed,
        on_run=lambda name, path: print(f"pizero chaos: {name} run in {path}", file=sys.stderr, flush=True))
    print(json.dumps(report))
    return 0 if report["identical"] else 1
