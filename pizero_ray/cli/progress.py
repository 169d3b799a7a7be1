"""What training shows on stderr while it runs: a rich progress bar on a terminal, else one line per iteration."""

from __future__ import annotations

import sys
import time


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


def first_iteration_note(info: dict) -> str:
    """Why the first iteration is slow, said before it starts: a newcomer otherwise waits in silence."""
    what = "starts the workers and compiles the rollout" if info["workers"] else "compiles the training step"
    return f"pizero: the first iteration {what} (cached for later runs): it takes longer than the rest"


def clock(seconds: float) -> str:
    """H:MM:SS or M:SS."""
    seconds = max(0, int(round(seconds)))
    hours, rest = divmod(seconds, 3600)
    return f"{hours}:{rest // 60:02d}:{rest % 60:02d}" if hours else f"{rest // 60}:{rest % 60:02d}"


class _Remaining:
    """How long the run has left: by its wall-clock budget (the metrics' training time against --minutes), by
    its iteration target at this session's pace, whichever ends first; None with neither known yet."""

    def __init__(self, options):
        self.options, self.started, self.first = options, time.time(), None

    def __call__(self, row: dict) -> float | None:
        if self.first is None:
            self.first = row["iteration"] - 1  # the session's first iteration: its pace counts from there
        left = []
        if self.options.minutes is not None:
            left.append(60.0 * self.options.minutes - row["wall_time_s"])
        done = row["iteration"] - self.first
        if self.options.iterations is not None and done > 0:
            pace = (time.time() - self.started) / done
            left.append(pace * (self.options.iterations - row["iteration"]))
        return max(0.0, min(left)) if left else None


def _line_callbacks(options):
    remaining = _Remaining(options)

    def on_start(info):
        print(_start_line(info), file=sys.stderr, flush=True)
        print(first_iteration_note(info), file=sys.stderr, flush=True)

    def on_iteration(row):
        extra = f" eval {row['eval_mean_score']:.4f}" if "eval_mean_score" in row else ""
        total = f"/{options.iterations}" if options.iterations else ""
        budget = f", {clock(row['wall_time_s'])} of {clock(60 * options.minutes)} trained" if options.minutes else ""
        left = remaining(row)
        eta = f", ETA {clock(left)}" if left is not None else ""
        print(f"iteration {row['iteration']}{total} mean score {row['mean_score']:.4f}"
              f"{extra} ({row['iteration_time_s']:.2f} s{budget}{eta})", file=sys.stderr, flush=True)

    return on_start, on_iteration, lambda: None


def _bar_callbacks(options, console):
    from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

    # A run with an iteration target counts iterations; one with a budget alone counts its training seconds.
    by_time = options.iterations is None
    progress = Progress(
        TextColumn("{task.fields[done]}"), BarColumn(), TextColumn("score {task.fields[score]}"),
        TextColumn("{task.fields[rate]} it/s"), TimeElapsedColumn(), TextColumn("ETA {task.fields[eta]}"),
        console=console,
    )
    remaining = _Remaining(options)
    task = None

    def on_start(info):
        nonlocal task
        console.print(_start_line(info))
        console.print(first_iteration_note(info))
        progress.start()
        total = 60.0 * options.minutes if by_time else options.iterations
        task = progress.add_task("train", total=total, completed=0 if by_time else info["start_iteration"],
                                 score="-", rate="-", eta="-", done=f"iteration {info['start_iteration']}")

    def on_iteration(row):
        score = f"{row['mean_score']:.4f}"
        if "eval_mean_score" in row:
            score += f" (eval {row['eval_mean_score']:.4f})"
        left = remaining(row)
        done = (f"iteration {row['iteration']}, {clock(row['wall_time_s'])} of {clock(60 * options.minutes)}"
                if by_time else f"iteration {row['iteration']}/{options.iterations}")
        progress.update(task, completed=row["wall_time_s"] if by_time else row["iteration"], score=score,
                        rate=f"{1.0 / row['iteration_time_s']:.2f}", eta=clock(left) if left is not None else "-",
                        done=done)

    return on_start, on_iteration, progress.stop


def summary_line(result: dict, seen: dict, options, seconds: float) -> str:
    """One line for a person, before the JSON line for programs: what this session trained, in how long, and the
    last evaluation it made. ``seen``: the session's "first" and "last" rows and its last "evaluated" one."""
    if "last" not in seen:
        return f"pizero: nothing trained: the run is at iteration {result['iteration']}"
    first, last = seen["first"]["iteration"], seen["last"]["iteration"]
    parts = [f"pizero: trained iterations {first}-{last} ({last - first + 1}) in {clock(seconds)}",
             f"{clock(seen['last']['wall_time_s'])} of training time in all"]
    if options.minutes is not None:
        parts[-1] += f" of the {options.minutes:g}-minute budget"
    if "evaluated" in seen:
        parts.append(f"last evaluation {seen['evaluated']['eval_mean_score']:.4f} at iteration "
                     f"{seen['evaluated']['iteration']}")
    return "; ".join(parts)


class stage:
    """A step that runs in silence (one compiled call: no progress to show inside it), said on stderr when it
    starts and when it ends, with its time: ``with stage("pizero eval", "playing 1000 episodes"): ...``."""

    def __init__(self, command: str, doing: str):
        self.command, self.doing = command, doing

    def __enter__(self):
        self.started = time.time()
        print(f"{self.command}: {self.doing} (the first call compiles; cached for later runs)...", file=sys.stderr,
              flush=True)
        return self

    def __exit__(self, kind, error, traceback):
        if kind is None:
            print(f"{self.command}: done in {clock(time.time() - self.started)}", file=sys.stderr, flush=True)
