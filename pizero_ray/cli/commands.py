"""The ``pizero`` command: one subcommand per family module (training, reports, experiments).

The thin impure shell: parse and validate everything first (bad input is one
line on stderr, exit code 2, nothing written), then call into the driver.
"""

from __future__ import annotations

import argparse
import os
import sys
from typing import Callable, NamedTuple

from pizero_ray.cli import compare, experiments, reports, training
from pizero_ray.cli.arguments import UsageError
from pizero_ray.config import ConfigError
from pizero_ray.storage.checkpoints import CheckpointError
from pizero_ray.storage.writer_lock import RunDirInUse, RunDirUnwritable


class Command(NamedTuple):
    add_parser: Callable[[object], None]  # adds the command's subparser to add_subparsers' result
    run: Callable[[argparse.Namespace], int]  # its exit code


# In the order `pizero --help` lists them.
COMMANDS = {
    "train": Command(training.add_train_parser, training.cmd_train),
    "chaos": Command(training.add_chaos_parser, training.cmd_chaos),
    "resume": Command(training.add_resume_parser, training.cmd_resume),
    "eval": Command(reports.add_eval_parser, reports.cmd_eval),
    "compare": Command(compare.add_compare_parser, compare.cmd_compare),
    "render": Command(reports.add_render_parser, reports.cmd_render),
    "inspect": Command(reports.add_inspect_parser, reports.cmd_inspect),
    "bench": Command(reports.add_bench_parser, reports.cmd_bench),
    "experiment": Command(experiments.add_experiment_parser, experiments.cmd_experiment),
    "plot-experiment": Command(experiments.add_plot_experiment_parser, experiments.cmd_plot_experiment),
    "plot": Command(reports.add_plot_parser, reports.cmd_plot),
}


class _Parser(argparse.ArgumentParser):
    """argparse, with a usage error in one line that says where the usage is, instead of the whole usage first:
    the line that matters is the one a user sees."""

    def error(self, message: str):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def build_parser() -> argparse.ArgumentParser:
    from pizero_ray import __version__

    parser = _Parser(prog="pizero", description="PiZero trained by OpenAI-ES on Ray")
    parser.add_argument("--version", action="version", version=f"pizero-ray {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)
    for command in COMMANDS.values():
        command.add_parser(sub)
    for command_parser in sub.choices.values():
        command_parser.add_argument("--verbose", action="store_true",
                                    help="on an unexpected error, show its whole traceback, not one line")
    return parser


def _unexpected(error: BaseException) -> str:
    """One line for an error no check foresaw: its type and its message's first line."""
    lines = [line.strip() for line in str(error).splitlines() if line.strip()]
    return f"{type(error).__name__}: {lines[0]}" if lines else type(error).__name__


def main(argv: list[str] | None = None) -> int:
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    # On a GPU node the driver (or bench, eval) needs a few MB of the GPU; JAX's
    # default of taking 75% of it up front would starve the workers beside it.
    os.environ.setdefault("XLA_PYTHON_CLIENT_PREALLOCATE", "false")
    args = build_parser().parse_args(argv)
    try:
        return COMMANDS[args.command].run(args)
    except (ConfigError, UsageError, CheckpointError, RunDirInUse, RunDirUnwritable) as error:
        print(f"pizero: error: {error}", file=sys.stderr)
        return 2
    except Exception as error:  # noqa: BLE001 -- the promise is one line; --verbose shows the rest
        if args.verbose:
            raise
        print(f"pizero: error: {_unexpected(error)} (run again with --verbose for the traceback)", file=sys.stderr)
        return 1


if __name__ == "__main__":
    sys.exit(main())
