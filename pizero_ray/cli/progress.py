"""What training shows on stderr while it runs: a rich progress bar on a terminal, else one line per iteration."""

from __future__ import annotations

import sys


def progress_callbacks(options, no_progress: bool):
    """(on_start, on_iteration, close) for ``driver.train``: a rich progress bar, or plain lines."""
    from rich.console import Console

    console = Console(stderr=True)
    if no_progress or not console.is_terminal:  # a log file or a pipe wants whole lines, not redraws
        return _line_callbacks(options)
    return _bar_callbacks(options, console)


def _start_line(info: dict) -> str:
    """Where the run trains and from where; the workers asked for (the rows say how many are live)."""
    parts = [info["connection"]]
    if info["workers"]:  # ES: a baseline trains in this process
        parts.append(f"asking for {info['workers']} worker{'' if info['workers'] == 1 else 's'}")
    parts += [f"{info['parameters']} parameters", f"starting at iteration {info['start_iteration']}"]
    return "pizero: " + ", ".join(parts)


def _line_callbacks(options):
    def on_start(info):
        print(_start_line(info), file=sys.stderr, flush=True)

    def on_iteration(row):
        extra = f" eval {row['eval_mean_score']:.4f}" if "eval_mean_score" in row else ""
        total = f"/{options.iterations}" if options.iterations else ""
        print(f"iteration {row['iteration']}{total} mean score {row['mean_score']:.4f}"
              f"{extra} ({row['iteration_time_s']:.2f} s)", file=sys.stderr, flush=True)

    return on_start, on_iteration, lambda: None


def _bar_callbacks(options, console):
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
        console.print(_start_line(info))
        progress.start()
        task = progress.add_task("train", total=options.iterations, completed=info["start_iteration"],
                                 score="-", rate="-")

    def on_iteration(row):
        score = f"{row['mean_score']:.4f}"
        if "eval_mean_score" in row:
            score += f" (eval {row['eval_mean_score']:.4f})"
        progress.update(task, completed=row["iteration"], score=score, rate=f"{1.0 / row['iteration_time_s']:.2f}")

    return on_start, on_iteration, progress.stop
