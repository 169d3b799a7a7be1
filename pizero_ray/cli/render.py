"""Drawing what a run's agent does: a PNG of one frame or a GIF of whole episodes.

Each frame is the environment's drawing of the state, made legible and
captioned (environment, step, score so far) by ``pizero_ray.cli.caption``.
"""

from __future__ import annotations

import contextlib
from pathlib import Path
from typing import NamedTuple

import numpy as np

from pizero_ray.agent.episodes import Trajectory
from pizero_ray.cli import caption
from pizero_ray.config import ConfigError
from pizero_ray.envs.base import Environment

FRAME_MS = 350


class Shot(NamedTuple):
    """One frame's worth of an episode: the state after ``step`` steps and the score (summed rewards) so far."""

    state: object  # unbatched env state
    step: int
    score: float
    final: bool  # the episode ended here


class Played(NamedTuple):
    env: Environment
    episodes: list[list[Shot]]


def _unbatch(tree, *index):
    import jax

    return jax.tree_util.tree_map(lambda x: np.asarray(x)[index], tree)


def episode_shots(trajectory: Trajectory, e: int) -> list[Shot]:
    """Episode ``e`` of a recorded batch: its initial state, then one shot per step up to its end.

    Scores add the rewards in float32 one step at a time, as the rollout does, so the
    final shot's score is the episode's score exactly.
    """
    rewards, dones = np.asarray(trajectory.rewards)[:, e], np.asarray(trajectory.dones)[:, e]
    scores = np.cumsum(rewards, dtype=np.float32)
    shots = [Shot(_unbatch(trajectory.initial_state, e), 0, 0.0, False)]
    for t in range(len(rewards)):
        final = bool(dones[t]) or t == len(rewards) - 1
        shots.append(Shot(_unbatch(trajectory.states, t, e), t + 1, float(scores[t]), final))
        if final:
            break
    return shots


def play(run_path: Path, episodes: int, seed: int, env_args: dict | None = None,
         trust_env: bool | str = False, playing=contextlib.nullcontext) -> Played:
    """``episodes`` episodes played by the run's unperturbed agent (its newest checkpoint), every step kept;
    ``trust_env`` as for ``methods.load_run``; ``playing()`` a context around the playing, once the run is
    loaded."""
    import jax

    from pizero_ray import methods
    from pizero_ray.agent import episodes as play_episodes

    config, _, theta, env, layout, agent = methods.load_run(run_path, env_args, trust_env)
    if env.render is None:
        raise ConfigError(f"environment {config.env!r} has no renderer")
    record = jax.jit(lambda th, key: play_episodes.record_episodes(agent, layout.unravel(th), env, key, episodes))
    with playing():
        trajectory = jax.device_get(record(theta, jax.random.PRNGKey(seed)))
    return Played(env, [episode_shots(trajectory, e) for e in range(episodes)])


def shot_caption(env: Environment, shot: Shot) -> list[str]:
    """The caption lines of one shot: environment, step / horizon, score so far and the environment's measures."""
    return caption.caption_lines(env.name, shot.state, shot.step, env.spec.horizon, shot.score, shot.final)


def episode_frames(run_path: Path, episodes: int, seed: int, env_args: dict | None = None,
                   trust_env: bool | str = False, playing=contextlib.nullcontext) -> list[np.ndarray]:
    """Frames of ``episodes`` episodes played by the unperturbed agent, each up to its end, legible and captioned."""
    played = play(run_path, episodes, seed, env_args, trust_env, playing)
    env = played.env
    return [caption.annotate(env.render(shot.state), shot_caption(env, shot))
            for episode in played.episodes for shot in episode]


def write(frames: list[np.ndarray], out: Path) -> Path:
    """``.png``: the last frame (the finished episode); ``.gif``: every frame."""
    from PIL import Image

    suffix = out.suffix.lower()
    if suffix not in (".png", ".gif"):
        raise ConfigError(f"--out must end in .png or .gif, got {out}")
    out.parent.mkdir(parents=True, exist_ok=True)
    images = [Image.fromarray(frame) for frame in frames]
    tmp = out.with_name(out.name + ".tmp")
    if suffix == ".png":
        images[-1].save(tmp, format="PNG")
    else:
        images[0].save(tmp, format="GIF", save_all=True, append_images=images[1:], duration=FRAME_MS, loop=0)
    tmp.replace(out)
    return out
