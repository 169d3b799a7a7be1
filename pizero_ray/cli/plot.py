"""Learning curves from metrics.jsonl, drawn with matplotlib (no display needed)."""

from __future__ import annotations

from pathlib import Path

from pizero_ray.storage import run_dir as rundir


def plot_runs(run_paths: list[Path], labels: list[str], out: Path, title: str | None = None) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    config = rundir.read_config(run_paths[0])
    tsp = config.env == "tsp"
    fig, axes = plt.subplots(1, 2, figsize=(11, 4))
    for path, label in zip(run_paths, labels):
        evals = rundir.evaluated_rows(path)
        sign = -1.0 if tsp else 1.0  # TSP reads better as tour length
        for ax, x_key in zip(axes, ("iteration", "wall_time_s")):
            xs = [r[x_key] / (60.0 if x_key == "wall_time_s" else 1.0) for r in evals]
            ax.plot(xs, [sign * r["eval_mean_score"] for r in evals], marker=".", label=label)
    for ax, xlabel in zip(axes, ("iteration", "wall-clock minutes")):
        ax.set_xlabel(xlabel)
        ax.set_ylabel("evaluated mean tour length" if tsp else "evaluated mean score")
        ax.grid(alpha=0.3)
        ax.legend()
    fig.suptitle(title or f"{config.env}: unperturbed agent on held-out episodes")
    fig.tight_layout()
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out, dpi=110)
    plt.close(fig)
