"""Learning curves from committed run summaries (scripts/summarise_runs.py), whose run dirs may be gone.

Usage::

    python scripts/plot_summary_curves.py --out docs/X.png --title "what is compared" \
        "LABEL=SUMMARY_JSON:RUN_KEY" ...

Each curve is the run RUN_KEY of SUMMARY_JSON's "runs": its evaluated score against iteration and against
wall-clock minutes, drawn as `pizero plot` draws run dirs.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pizero_ray.cli.plot import plot_curves  # noqa: E402


def summary_curve(summary_path: Path, run_key: str) -> tuple[str, list[dict]]:
    """The env and the evaluated rows of one summarised run."""
    runs = json.loads(summary_path.read_text())["runs"]
    if run_key not in runs:
        raise SystemExit(f"{summary_path} has no run {run_key!r} (it has: {', '.join(sorted(runs))})")
    run = runs[run_key]
    rows = [{"iteration": it, "eval_mean_score": score, "wall_time_s": wall}
            for it, score, wall in run["curve_iteration_score_wall_s"]]
    return run["env"], rows


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("curves", nargs="+", metavar="LABEL=SUMMARY_JSON:RUN_KEY")
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--title", required=True)
    args = parser.parse_args(argv)
    curves, envs = [], set()
    for spec in args.curves:
        label, _, source = spec.partition("=")
        path, _, run_key = source.rpartition(":")
        if not label or not path or not run_key:
            parser.error(f"a curve must read LABEL=SUMMARY_JSON:RUN_KEY, got {spec!r}")
        env, rows = summary_curve(Path(path), run_key)
        envs.add(env)
        curves.append((label, rows))
    plot_curves(curves, args.out, args.title, tour_length=envs == {"tsp"})
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
