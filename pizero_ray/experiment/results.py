"""An experiment's results: curves on the wall-clock grid, the results figure, and the table.

Reads only run dirs (metrics.jsonl is the source of truth) and the
experiment's spec; Tune's own records are not needed. The reference solvers
(random, heuristics, optimal) are scored once per environment on the
learning curve's own evaluation episodes and cached in OUT/references.json.
"""

from __future__ import annotations

import json
import os
import platform
import time
from pathlib import Path

import numpy as np

from pizero_ray.experiment import bands, grid

REFERENCES_FILE = "references.json"
VARIANT_OF = {"flp-mean": "flp", "pacman-po": "pacman"}  # drawn alike: the states figure shows one of each
METHOD_LABELS = {"pizero": "PiZero (ES + planner)", "es": "ES, no planner", "alphazero": "AlphaZero (simulator)",
                 "muzero": "MuZero (learned model)"}


def marks_s(experiment: grid.Experiment) -> np.ndarray:
    """The evaluation marks, in training seconds: 0, every --eval-every-minutes, and the budget."""
    every, budget = 60.0 * experiment.eval_every_minutes, 60.0 * experiment.budget_minutes
    return np.unique(np.append(np.arange(0.0, budget, every), budget))


def curves(out: Path, experiment: grid.Experiment) -> dict[tuple[str, str], np.ndarray]:
    """(env, method) -> [finished seeds, marks] evaluated scores. A trial counts once it has spent its budget."""
    from pizero_ray.storage import run_dir as rundir

    marks = marks_s(experiment)
    found: dict[tuple[str, str], list[np.ndarray]] = {}
    for trial in experiment.trials:
        rows = rundir.evaluated_rows(grid.run_path(out, trial))
        if experiment.final_evaluation(rows) is None:
            continue  # not started, or not finished: no final score yet
        times = np.array([row["wall_time_s"] for row in rows])
        scores = np.array([row["eval_mean_score"] for row in rows])
        found.setdefault((trial.env, trial.method), []).append(bands.curve_at(times, scores, marks))
    return {key: np.stack(rows) for key, rows in found.items()}


def references(out: Path, experiment: grid.Experiment) -> dict[str, dict[str, float]]:
    """env -> {solver: mean score} on the learning curve's evaluation episodes (cached in OUT/references.json)."""
    path = out / REFERENCES_FILE
    cached = json.loads(path.read_text()) if path.exists() else {}
    missing = [env for env in experiment.envs if env not in cached]
    for env in missing:
        cached[env] = _reference_scores(experiment, env)
    if missing:
        tmp = path.with_name(REFERENCES_FILE + ".tmp")
        tmp.write_text(json.dumps(cached, indent=1) + "\n")
        tmp.replace(path)
    return {env: cached[env] for env in experiment.envs}


def _reference_scores(experiment: grid.Experiment, env_name: str) -> dict[str, float]:
    import jax

    from pizero_ray import methods
    from pizero_ray.agent import episodes
    from pizero_ray.evaluation.runs import EVAL_SEED

    config = experiment.config(grid.Trial(env_name, "pizero", 0))
    env = methods.other_env(config, methods.make_env(config), dict(dict(experiment.eval_env_args).get(env_name, ())))
    if env.references is None:
        return {}
    keys = episodes.episode_reset_keys(jax.random.PRNGKey(EVAL_SEED), experiment.eval_episodes)
    initial_states, _ = jax.vmap(env.reset)(keys)
    found = env.references(initial_states, np.zeros(experiment.eval_episodes))
    return {name[:-len("_score")]: value for name, value in found.items()
            if name.endswith("_score") and not name.startswith("mean")}


def _shown(env: str, values):
    """TSP reads as tour length (minus its score), every other environment as its score."""
    return -np.asarray(values) if env == "tsp" else np.asarray(values)


def _y_label(env: str) -> str:
    return "tour length (lower is better)" if env == "tsp" else "evaluated score"


def machine() -> str:
    return f"{platform.machine()} {os.cpu_count()} cores, {platform.system()}"


def summarise(experiment: grid.Experiment, found: dict, refs: dict) -> dict:
    """Per (env, method): the final mean score, its BCa 95% CI, and seeds; the references; the setting.

    ``found``: ``curves``; ``refs``: ``references``.
    """
    rows = []
    for (env, method), runs_ in sorted(found.items(),
                                       key=lambda kv: (experiment.envs.index(kv[0][0]),
                                                       experiment.methods.index(kv[0][1]))):
        final = runs_[:, -1]
        low, high = bands.bca_interval(final)
        rows.append({"env": env, "method": method, "seeds": int(final.size), "mean_score": float(final.mean()),
                     "ci95_bca": [low, high], "seed_scores": [float(v) for v in final]})
    return {"budget_minutes": experiment.budget_minutes, "eval_episodes": experiment.eval_episodes,
            "cpus_per_trial": experiment.cpus_per_trial, "seeds_asked": experiment.seeds,
            "machine": machine(), "date": time.strftime("%Y-%m-%d"), "results": rows, "references": refs}


def table_markdown(summary: dict) -> str:
    """The results table: one row per (env, method) with a final score, the references beside each env."""
    lines = [f"Budget {summary['budget_minutes']:g} training minutes per run, {summary['cpus_per_trial']} CPU(s) each; "
             f"{summary['eval_episodes']} evaluation episodes; {summary['machine']}; {summary['date']}.", "",
             "| env | method | final mean score | 95% CI (BCa) | seeds | references (same episodes) |",
             "|---|---|---|---|---|---|"]
    for row in summary["results"]:
        refs = summary["references"].get(row["env"], {})
        shown = ", ".join(f"{name.replace('_', ' ')} {value:.4g}" for name, value in sorted(refs.items()))
        low, high = row["ci95_bca"]
        lines.append(f"| {row['env']} | {row['method']} | {row['mean_score']:.4g} | [{low:.4g}, {high:.4g}] | "
                     f"{row['seeds']} | {shown} |")
    return "\n".join(lines) + "\n"


def results_figure(experiment: grid.Experiment, found: dict, refs: dict, png: Path) -> None:
    """One panel per environment: mean evaluated score against training minutes, BCa bands, references.

    ``found``: ``curves``; ``refs``: ``references``.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    minutes = marks_s(experiment) / 60.0
    columns = min(4, len(experiment.envs))
    rows = -(-len(experiment.envs) // columns)
    fig, axes = plt.subplots(rows, columns, figsize=(4.6 * columns, 3.8 * rows), squeeze=False)
    for ax, env in zip(axes.flat, experiment.envs):
        for colour, method in zip(plt.rcParams["axes.prop_cycle"].by_key()["color"], experiment.methods):
            if (env, method) not in found:
                continue
            mean, low, high = bands.mean_band(found[env, method])
            seeds = found[env, method].shape[0]
            ax.plot(minutes, _shown(env, mean), color=colour, marker=".", label=f"{METHOD_LABELS[method]} ({seeds})")
            ax.fill_between(minutes, _shown(env, low), _shown(env, high), color=colour, alpha=0.2, linewidth=0)
        for name, value in sorted(refs.get(env, {}).items()):
            ax.axhline(float(_shown(env, value)), color="0.45", linestyle="--", linewidth=0.8)
            ax.annotate(name.replace("_", " "), (minutes[-1], float(_shown(env, value))), fontsize=7,
                        color="0.3", ha="right", va="bottom")
        ax.set_title(env)
        ax.set_xlabel("training minutes")
        ax.set_ylabel(_y_label(env))
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, title="method (seeds)", title_fontsize=7)
    for ax in list(axes.flat)[len(experiment.envs):]:
        ax.set_visible(False)
    fig.suptitle(f"Equal wall-clock: {experiment.budget_minutes:g} training minutes per run, "
                 f"{experiment.cpus_per_trial} CPU each\n{machine()}; mean across seeds, 95% BCa band", fontsize=10)
    fig.tight_layout()
    png.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(png, dpi=110)
    plt.close(fig)


def state_runs(sittings: list[tuple[Path, grid.Experiment]], limit: int = 6) -> dict[str, Path]:
    """env -> the run whose agent the states figure shows: seed 0 of the first method listed that has one.

    One panel per family of environments: flp-mean and pacman-po only where flp or pacman is not in the grid.
    """
    all_envs = {env for _, experiment in sittings for env in experiment.envs}
    shown = {}
    for out, experiment in sittings:
        for env in [env for env in experiment.envs if VARIANT_OF.get(env) not in all_envs]:
            for method in experiment.methods:
                path = grid.run_path(out, grid.Trial(env, method, 0))
                if path.exists() and len(shown) < limit:
                    shown[env] = path
                    break
    return shown


def write_report(sittings: list[tuple[Path, grid.Experiment]], docs: Path) -> dict:
    """results.png, results_table.md and results.json in ``docs`` for one or more sittings; returns the summary.

    Each sitting is (its --out, its spec); ``grid.combine`` checks they are one experiment.
    """
    experiment = grid.combine([spec for _, spec in sittings])
    found, refs = {}, {}
    for out, spec in sittings:
        found.update(curves(out, spec))
        refs.update(references(out, spec))
    summary = summarise(experiment, found, refs)
    docs.mkdir(parents=True, exist_ok=True)
    results_figure(experiment, found, refs, docs / "results.png")
    (docs / "results_table.md").write_text(table_markdown(summary))
    (docs / "results.json").write_text(json.dumps(summary, indent=1) + "\n")
    return summary
