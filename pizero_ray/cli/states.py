"""The paper's states figure: one final state per environment, as each run's agent leaves it."""

from __future__ import annotations

import math
from pathlib import Path
from typing import NamedTuple

import numpy as np

from pizero_ray.cli import caption, render
from pizero_ray.config import ConfigError
from pizero_ray.storage import run_dir as rundir

MAX_PANELS = 6
PANEL_INCHES = (4.0, 4.8)  # width, height of one panel: the state, its title above and its notes below
DPI = 150


class Panel(NamedTuple):
    title: str
    image: np.ndarray  # the environment's drawing of the final state
    notes: list[str]  # the score, and what it means (TSP: tour and optimal tour lengths)


def grid_shape(count: int) -> tuple[int, int]:
    """(rows, columns): up to three panels side by side, four as 2x2, five or six as 2x3."""
    if not 1 <= count <= MAX_PANELS:
        raise ConfigError(f"the states figure takes 1..{MAX_PANELS} environments, got {count}")
    columns = 2 if count == 4 else min(count, 3)
    return math.ceil(count / columns), columns


def final_state_panel(env_name: str, run_path: Path, seed: int, env_args: dict | None = None,
                      trust_env: bool | str = False) -> Panel:
    """One evaluation episode of the run's agent (as ``pizero render`` plays it), drawn at its end.

    ``env_args``: parameters of the environment it is played on, over the run's (Sokoban: valid levels).
    """
    config = rundir.read_config(run_path)  # a one-line error naming a path that is no run dir
    if config.env != env_name:
        raise ConfigError(f"run dir {run_path} is a {config.env!r} run, not {env_name!r}")
    played = render.play(run_path, episodes=1, seed=seed, env_args=env_args, trust_env=trust_env)
    last = played.episodes[0][-1]
    notes = [f"score {caption.format_score(last.score)}", *caption.measures(env_name, last.state, last.final)]
    return Panel(caption.title(env_name), played.env.render(last.state), notes)


def draw_panels(panels: list[Panel], out: Path, title: str | None = None) -> Path:
    """The panels in a grid (matplotlib, Agg), each titled above and annotated below; written as PNG.

    ``title``: a line above the grid (the experiment's budget, say); the figure keeps its size.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows, columns = grid_shape(len(panels))
    fig, axes = plt.subplots(rows, columns, figsize=(PANEL_INCHES[0] * columns, PANEL_INCHES[1] * rows),
                             squeeze=False)
    for ax in axes.flat:
        ax.axis("off")
    for ax, panel in zip(axes.flat, panels):
        ax.imshow(panel.image, interpolation="antialiased")
        ax.set_title(panel.title, fontsize=13)
        ax.text(0.5, -0.03, "\n".join(panel.notes), transform=ax.transAxes, ha="center", va="top", fontsize=10)
    top = 0.94
    if title:
        fig.suptitle(title, fontsize=12, y=0.995, va="top")
        top -= 0.3 / (PANEL_INCHES[1] * rows)  # room for it: 0.3 inch
    fig.subplots_adjust(left=0.02, right=0.98, top=top, bottom=0.07, wspace=0.08, hspace=0.3)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = out.with_name(out.name + ".tmp")
    fig.savefig(tmp, dpi=DPI, format="png")  # no bbox_inches="tight": the size says the grid
    plt.close(fig)
    tmp.replace(out)
    return out


def states_figure(run_paths: dict[str, Path], out: Path, seed: int = 0,
                  env_args: dict[str, dict] | None = None, title: str | None = None,
                  trust_env: bool = False) -> Path:
    """Up to six environments (env name -> run dir): each run's final state of one episode, in a grid PNG.

    ``env_args``: env name -> the parameters to play it with, over the run's own; ``title``: above the grid;
    ``trust_env``: import the environments run dirs name by import path (``methods.load_run``).
    """
    out = Path(out)
    if out.suffix.lower() != ".png":
        raise ConfigError(f"the states figure is a .png, got {out}")
    grid_shape(len(run_paths))  # the count is checked before any episode is played
    panels = [final_state_panel(name, Path(path), seed, (env_args or {}).get(name), trust_env)
              for name, path in run_paths.items()]
    return draw_panels(panels, out, title)
