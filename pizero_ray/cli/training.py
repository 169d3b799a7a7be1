"""`pizero train`, `resume` and `chaos`: check every input, write the run dir, then hand over to the driver."""

from __future__ import annotations

import argparse
import dataclasses
import json
import signal
import sys
from pathlib import Path

from pizero_ray.api import DEFAULT_ITERATIONS
from pizero_ray.cli.arguments import (
    UsageError,
    add_env_trust_options,
    add_settings,
    env_trust,
    existing_run,
    given,
    non_negative_int,
    positive_int,
)
from pizero_ray.config import Config, ConfigError, build_config
from pizero_ray.presets import PRESETS
from pizero_ray.settings import lookup
from pizero_ray.storage import run_dir as rundir
from pizero_ray.storage import writer_lock


def _add_run_options(parser: argparse.ArgumentParser) -> None:
    """How to run (RunOptions and its PoolOptions); shared by train, chaos and resume."""
    from pizero_ray.trainer.options import RunOptions

    add_settings(parser, RunOptions, show_defaults=True)
    parser.add_argument("--no-progress", action="store_true", help="print one line per iteration instead of a bar")


# What --help says of the config's defaults: they are one preset's on one environment.
CONFIG_DEFAULTS_NOTE = (f"The config options' defaults shown are --preset default's on --env {Config.env} with "
                        f"--method {Config.method}; other environments, methods and presets change some of them: "
                        "docs/options.md lists each.")


def _add_config_options(parser: argparse.ArgumentParser) -> None:
    """What the run computes (the Config); shared by train and chaos. --help shows the 'default' preset's
    values on the default environment, and says so (CONFIG_DEFAULTS_NOTE)."""
    from pizero_ray.presets import preset_values

    parser.add_argument("--preset", default="default", help=f"one of {', '.join(PRESETS)} (default default)")
    add_settings(parser, Config, show_defaults=True, defaults=preset_values("default", Config.env, Config.method))


def add_train_parser(sub) -> None:
    train = sub.add_parser("train", help="train a new run", description=CONFIG_DEFAULTS_NOTE)
    train.add_argument("--run-dir", required=True,
                       help="the run's directory (created): config.json, checkpoints, metrics; refused if it "
                            "already holds a run")
    _add_config_options(train)
    _add_run_options(train)


def add_chaos_parser(sub) -> None:
    chaos = sub.add_parser("chaos", help="train twice, once while killing workers, and compare the parameters",
                           description=CONFIG_DEFAULTS_NOTE)
    chaos.add_argument("--run-dir", required=True, help="gets clean/ and chaos/ run dirs")
    chaos.add_argument("--kills", type=positive_int, default=3, help="worker processes to SIGKILL (default 3)")
    chaos.add_argument("--chaos-seed", type=non_negative_int, default=0, help="where the kills fall")
    _add_config_options(chaos)
    _add_run_options(chaos)


def add_resume_parser(sub) -> None:
    resume = sub.add_parser("resume", help="continue a run from its newest checkpoint")
    resume.add_argument("run_dir")
    add_env_trust_options(resume)
    resume.add_argument("--restart", action="store_true",
                        help="start again from iteration 0 although the run dir holds progress; what it replaces "
                             "is kept (checkpoints in RUN_DIR/replaced/, metrics rows in metrics-dropped.jsonl)")
    _add_run_options(resume)


def train_config(args) -> Config:
    """The config given (over its preset), its environment parameters and warm start checked (``api``)."""
    from pizero_ray import api

    config = api.new_run_config(args.preset, **given(Config, args))
    _note_a_smaller_chunk(args, config)
    return config


def _note_a_smaller_chunk(args, config: Config) -> None:
    """Says so when a population that the preset's chunk does not divide made the chunk smaller (a prime
    population makes chunks of one pair: as many calls as pairs)."""
    chosen = given(Config, args)
    if "chunk_size" in chosen or "population" not in chosen:
        return
    try:
        preset_chunk = build_config(args.preset, **{**chosen, "population": None}).chunk_size
    except ConfigError:  # the other settings need this population: nothing to compare with
        return
    if config.chunk_size < preset_chunk:
        print(f"pizero: note: --population {config.population} is no multiple of the preset's chunk of "
              f"{preset_chunk} pairs: chunks of {config.chunk_size} pairs, {config.num_chunks} of them "
              "(--chunk-size sets it)", file=sys.stderr)


def run_options(args, iterations: int | None, kept: dict | None = None, config: Config | None = None):
    """The run options given, over ``kept`` ones (RunOptions validates them: a bad one is a one-line ConfigError);
    with ``config``, also checked against it (pool options a baseline has no use for)."""
    from pizero_ray.trainer.options import PoolOptions, RunOptions

    # An empty text (--compile-cache '', --address '') means the default, as an absent option does.
    values = {name: value for name, value in given(RunOptions, args).items() if value != ""}
    if config is not None and config.gradient_trained:
        pool = sorted(set(values) & set(given(PoolOptions, args)))
        if pool:
            flags = ", ".join(lookup(PoolOptions, name).flag for name in pool)
            raise UsageError(f"method {config.method} trains in one process, without Ray workers: {flags} would "
                             "do nothing")
    options = RunOptions.create(**{**(kept or {}), **values, "iterations": iterations})
    if config is not None:
        options.pool.check_against(config)
    return options


def _run_training(run_path: Path, options, no_progress: bool, trains) -> int:
    """Runs ``trains(on_start, on_iteration)`` (``api.start_run`` or ``api.continue_run``) with the progress
    lines, then the summary and the JSON line; a training error is one line, exit code 1."""
    import time

    from pizero_ray.cli.progress import progress_callbacks, summary_line
    from pizero_ray.storage.checkpoints import CheckpointSaveError
    from pizero_ray.trainer import driver

    on_start, show_iteration, close = progress_callbacks(options, no_progress)
    seen: dict[str, dict] = {}  # this session's first and last rows, and its last evaluated one
    started = time.time()

    def on_iteration(row: dict) -> None:
        seen.setdefault("first", row)
        seen["last"] = row
        if "eval_mean_score" in row:
            seen["evaluated"] = row
        show_iteration(row)

    try:
        try:
            result = trains(on_start, on_iteration)
        finally:
            close()
    except (driver.TrainingError, CheckpointSaveError) as error:  # one line; the run's last checkpoint stands
        print(f"pizero: error: {error}", file=sys.stderr)
        return 1
    print(summary_line(result, seen, options, time.time() - started), file=sys.stderr)
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


def cmd_train(args) -> int:
    from pizero_ray import api

    config = train_config(args)
    run_path = rundir.resolve(args.run_dir)
    # With a wall-clock budget and no iteration target, the budget alone says when to stop.
    iterations = args.iterations or (None if args.minutes else DEFAULT_ITERATIONS)
    options = run_options(args, iterations, config=config)
    api.check_new_run(run_path, config, options)  # before the progress lines: a refusal is the only line
    return _run_training(run_path, options, args.no_progress,
                         lambda on_start, on_iteration: api.start_run(run_path, config, options, on_start,
                                                                      on_iteration))


def cmd_resume(args) -> int:
    from pizero_ray import api
    from pizero_ray.storage import runs

    run_path = existing_run(args.run_dir, env_trust(args))
    config = rundir.read_trusted_config(run_path, env_trust(args))
    if args.iterations is None and args.minutes is None:
        raise UsageError("resume needs --iterations N (the total number of iterations to reach), "
                         "--minutes M (the run's total wall-clock budget) or both")
    # The schedule goes on as the run dir says unless an --eval-* or --checkpoint-* option is given.
    kept = rundir.read_schedule(run_path)
    options = dataclasses.replace(run_options(args, args.iterations, kept, config=config), restart=args.restart)
    rundir.check_location(run_path)
    if not args.restart:
        runs.check_same_config(run_path, config)  # before anything is written (the driver checks it again)
    with writer_lock.hold(run_path):  # refused, in one line, while another process trains the run
        if not args.restart and not _say_where_the_run_stands(run_path, options):
            return 0
        return _run_training(run_path, options, args.no_progress,
                             lambda on_start, on_iteration: api.continue_run(run_path, config, options, on_start,
                                                                             on_iteration))


def _say_where_the_run_stands(run_path: Path, options) -> bool:
    """Says (stderr) where the resumed run stands against its targets; False when it has reached them (nothing
    to train: no Ray is started). Judged at its newest checkpoint, where the driver continues."""
    from pizero_ray.cli.progress import clock
    from pizero_ray.storage import checkpoints

    meta = checkpoints.newest_meta(run_path)
    iteration = meta["iteration"] if meta else 0
    trained_s = max((row["wall_time_s"] for row in rundir.read_metrics(run_path)
                     if row["iteration"] <= iteration and "wall_time_s" in row), default=0.0)
    used = f", {clock(trained_s)} of the {options.minutes:g}-minute budget trained" if options.minutes else ""
    done = ((options.iterations is not None and iteration >= options.iterations)
            or (options.minutes is not None and trained_s >= 60.0 * options.minutes))
    # Only a checkpoint whose files are as saved ends it here: a damaged one the driver quarantines, and it
    # trains on from the one before.
    intact = meta is not None and checkpoints.diagnose(
        run_path / checkpoints.CHECKPOINT_DIR / str(iteration)).verdict == "intact"
    if done and intact:
        print(f"pizero: run {run_path} is at iteration {iteration}{used}: nothing to train; give more with "
              f"--iterations or --minutes", file=sys.stderr)
        return False
    print(f"pizero: resuming run {run_path} at iteration {iteration}{used}", file=sys.stderr)
    return True


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
    options = run_options(args, args.iterations or 10, config=config)
    from pizero_ray import footprint, methods

    footprint.check_fits(config, methods.make_env(config), options.eval_episodes)
    report = chaos.compare_runs(
        base, config, options, kills=args.kills, seed=args.chaos_seed,
        on_run=lambda name, path: print(f"pizero chaos: {name} run in {path}", file=sys.stderr, flush=True))
    print(json.dumps(report))
    return 0 if report["identical"] else 1
