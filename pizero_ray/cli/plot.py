"""Learning curves drawn with matplotlib (no display needed): from run dirs' metrics.jsonl or from committed
summaries, whose run dirs may be gone."""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

from pizero_ray.storage import run_dir as rundir

# One learning curve: a label and its evaluated rows, each with iteration, wall_time_s and eval_mean_score.
Curve = tuple[str, Sequence[dict]]


def plot_curves(curves: Sequence[Curve], out: Path, title: str, tour_length: bool = False) -> None:
    """Score against iteration (left) and against wall-clock minutes (right), one line per curve."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    sign = -1.0 if tour_length else 1.0  # TSP's score is minus the tour, which reads better as the tour
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for label, rows in curves:
        for ax, x_key in zip(axes, ("iteration", "wall_time_s")):
            xs = [r[x_key] / (60.0 if x_key == "wall_time_s" else 1.0) for r in rows]
            ax.plot(xs, [sign * r["eval_mean_score"] for r in rows], marker=".", label=label)
    for ax, xlabel in zip(axes, ("iteration", "wall-clock minutes")):
        ax.set_xlabel(xlabel)
        ax.set_ylabel("evaluated mean tour length" if tour_length else "evaluated mean score")
        ax.grid(alpha=0.3)
        ax.legend()
    fig.suptitle(title)
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)


def plot_runs(run_paths: list[Path], labels: list[str], out: Path, title: str | None = None) -> None:
    env = rundir.read_config(run_paths[0]).env
    curves = [(label, rundir.evaluated_rows(path)) for path, label in zip(run_paths, labels)]
    plot_curves(curves, out, title or f"{env}: unperturbed agent on held-out episodes", tour_length=env == "tsp")
