"""`pizero experiment` and `plot-experiment`: a grid of (env, method, seed) runs on Ray Tune, and its report."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from pizero_ray.cli.arguments import UsageError, add_settings, comma_list, env_arg, given, positive_int
from pizero_ray.config import Config
from pizero_ray.presets import PRESETS
from pizero_ray.storage import run_dir as rundir

# The experiment's grid axes: every trial gets its own; the other Config settings apply to all trials.
_GRID_FIELDS = ("env", "method", "seed", "env_args")


def _env_scoped_arg(text: str) -> tuple[str, tuple[str, object]]:
    """ENV:KEY=VALUE, an environment parameter for one environment of an experiment. ENV is what precedes the
    last colon before the first "=": an import path has a colon of its own (examples.corridor:make:length=5)."""
    named, equals, value = text.partition("=")
    env, sep, key = named.rpartition(":")
    if not sep or not env or not equals:
        raise argparse.ArgumentTypeError(f"expected ENV:KEY=VALUE, got {text!r}")
    return env, env_arg(f"{key}={value}")


def add_experiment_parser(sub) -> None:
    from pizero_ray.config import METHODS

    experiment = sub.add_parser(
        "experiment", help="train every (env, method, seed) for the same wall-clock budget on Ray Tune; "
                           "run it again to resume an interrupted experiment")
    experiment.add_argument("--envs", type=comma_list, required=True, help="comma-separated environments")
    experiment.add_argument("--methods", type=comma_list, default=METHODS,
                            help=f"comma-separated methods (default {','.join(METHODS)})")
    experiment.add_argument("--seeds", type=positive_int, default=5, help="independent runs each (default 5)")
    experiment.add_argument("--budget-minutes", type=float, required=True,
                            help="training wall-clock per run (evaluations excluded)")
    experiment.add_argument("--eval-every-minutes", type=float, default=None,
                            help="evaluate at every multiple of this on each run's clock (default: budget / 5)")
    experiment.add_argument("--cpus-per-trial", type=positive_int, default=2,
                            help="CPUs each run holds: ES workers, or a baseline's process (default 2)")
    experiment.add_argument("--out", required=True, help="the experiment's directory (run dirs, Tune's state)")
    experiment.add_argument("--env-arg", dest="env_scoped_args", action="append", type=_env_scoped_arg,
                            default=[], metavar="ENV:KEY=VALUE", help="a parameter of one environment, repeatable")
    experiment.add_argument("--eval-env-arg", dest="eval_env_scoped_args", action="append", type=_env_scoped_arg,
                            default=[], metavar="ENV:KEY=VALUE",
                            help="evaluate that environment with this parameter changed (e.g. sokoban:levels=PATH)")
    experiment.add_argument("--eval-episodes", type=positive_int, default=256, help="episodes per evaluation")
    experiment.add_argument("--address", default=None, help="Ray cluster address (default: a local instance)")
    experiment.add_argument("--compile-cache", default=None, help="JAX persistent compile cache dir, or 'none'")
    experiment.add_argument("--preset", default="default", help=f"one of {', '.join(PRESETS)}, for every trial")
    add_settings(experiment, Config, show_defaults=False, exclude=_GRID_FIELDS)


def add_plot_experiment_parser(sub) -> None:
    report = sub.add_parser("plot-experiment", help="an experiment's results figure, table and states figure")
    report.add_argument("experiment_dirs", nargs="+", metavar="EXPERIMENT_DIR",
                        help="an experiment's --out; several: sittings of one experiment over other environments")
    report.add_argument("--out", required=True, help="directory for results.png, results_table.md, results.json")
    report.add_argument("--trust-env", action="store_true",
                        help="import the environments the experiment names by import path (their code runs)")


def _scoped(pairs) -> tuple:
    """[(env, (key, value))] -> ((env, ((key, value), ...)), ...), sorted."""
    by_env: dict[str, dict] = {}
    for env, (key, value) in pairs:
        by_env.setdefault(env, {})[key] = value
    return tuple(sorted((env, tuple(sorted(values.items()))) for env, values in by_env.items()))


def cmd_experiment(args) -> int:
    from pizero_ray.experiment import grid, runner

    overrides = {name: value for name, value in given(Config, args).items() if name not in _GRID_FIELDS}
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


def _refuse_untrusted_envs(sittings, trust_env: bool) -> None:
    """An experiment dir is data: the environments it names by import path are imported only with --trust-env."""
    from pizero_ray import envs

    for out, spec in sittings:
        named = [env for env in spec.envs if envs.is_import_path(env)]
        if named and not trust_env:
            raise UsageError(f"experiment {out} names environments by import path ({', '.join(named)}), which "
                             "would import and run that code; if you trust it, add --trust-env")


def cmd_plot_experiment(args) -> int:
    from pizero_ray.experiment import grid, results

    sittings = [(out, grid.read_spec(out)) for out in map(rundir.resolve, args.experiment_dirs)]
    _refuse_untrusted_envs(sittings, args.trust_env)
    summary = results.write_report(sittings, Path(args.out))
    shown = results.state_runs(sittings)
    if shown:
        from pizero_ray.cli.states import states_figure

        eval_env_args = {env: dict(values) for _, spec in sittings for env, values in spec.eval_env_args}
        methods = sorted({results.METHOD_LABELS[path.parent.name] for path in shown.values()})
        title = (f"Seed 0's {' / '.join(methods)} after {sittings[0][1].budget_minutes:g} training minutes: "
                 "one evaluation episode each")
        states_figure(shown, Path(args.out) / "states.png", env_args=eval_env_args,  # Sokoban on its valid levels
                      title=title, trust_env=args.trust_env)
    print(json.dumps({"out": args.out, "results": len(summary["results"]), "states": sorted(shown)}))
    return 0
