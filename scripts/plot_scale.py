"""The scale model's two figures from `pizero bench --scale --json`'s output.

Usage::

    python scripts/plot_scale.py docs/bench/SCALE.json --out docs/scale

writes ``<out>_measured.png`` (the driver's own CPU seconds per iteration
against chunks per iteration, one line per worker count, the parts on the
driver; stand-ins marked) and ``<out>_model.png`` (the model's efficiency at
512 workers against the parameters, one line per design, each chunk size in
its own panel).
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

SIZE_IN, DPI = (11, 4), 110


def plot_measured(rows: list[dict], out: Path) -> None:
    figure, axes = plt.subplots(1, 2, figsize=SIZE_IN, dpi=DPI)
    for axis, design in zip(axes, ("a_parts_on_driver", "a_parts_on_workers")):
        points = [row for row in rows if row["source"] == "measured" and row["design"] == design]
        batched = [row for row in rows if row["source"] == "measured" and row["design"] == design + "_8_per_call"]
        for row in batched:
            axis.plot([row["chunks"]], [row["driver_s"]], "k*", markersize=12)
        if batched:
            axis.plot([], [], "k*", label="8 chunks a call")
        for workers in sorted({row["workers"] for row in points}):
            line = sorted((row for row in points if row["workers"] == workers), key=lambda row: row["chunks"])
            label = f"{workers} workers" + (" (stand-ins)" if line[0]["stand_ins"] else "")
            axis.plot([row["chunks"] for row in line], [row["driver_s"] for row in line], "o-", label=label)
        axis.set(xscale="log", yscale="log", xlabel="chunks per iteration", ylabel="driver CPU s per iteration",
                 title=design.replace("_", " "))
        axis.legend(fontsize=8)
    figure.suptitle("The real driver against stub workers (this machine, 2 cores)")
    figure.tight_layout()
    figure.savefig(out)
    plt.close(figure)


def plot_model(rows: list[dict], out: Path, workers: int = 512) -> None:
    model = [row for row in rows if row["source"] == "model" and row["workers"] == workers]
    chunk_sizes = sorted({row["pairs_per_chunk"] for row in model})
    figure, axes = plt.subplots(1, len(chunk_sizes), figsize=SIZE_IN, dpi=DPI, squeeze=False)
    for axis, pairs in zip(axes[0], chunk_sizes):
        for design, style in zip(sorted({row["design"] for row in model}), ("o-", "s--", "^-", "x:")):
            line = sorted((row for row in model if row["design"] == design and row["pairs_per_chunk"] == pairs),
                          key=lambda row: row["parameters"])
            # dashed and dotted: parts on the driver and replayed updates lie almost on one another
            axis.plot([row["parameters"] for row in line], [row["efficiency"] for row in line], style,
                      label=design.replace("_", " "), markersize=7)
        axis.set(xscale="log", yscale="log", xlabel="parameters", ylabel="efficiency (rollout / iteration)",
                 title=f"{workers} GPU workers, chunks of {pairs:,} pairs", ylim=(1e-6, 1.5))
        axis.legend(fontsize=8)
    figure.suptitle("The scale model at 1M agent-steps/s per worker, 8 workers a node")
    figure.tight_layout()
    figure.savefig(out)
    plt.close(figure)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("result", type=Path)
    parser.add_argument("--out", type=Path, required=True, help="path prefix of the two PNGs")
    args = parser.parse_args(argv)
    rows = json.loads(args.result.read_text())["rows"]
    plot_measured(rows, args.out.with_name(args.out.name + "_measured.png"))
    plot_model(rows, args.out.with_name(args.out.name + "_model.png"))
    return 0


if __name__ == "__main__":
    sys.exit(main())
