"""Drawing what a run's agent does: a PNG of one frame or a GIF of whole episodes."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pizero_ray.config import ConfigError

FRAME_MS = 350


def _unbatch(tree, *index):
    import jax

    return jax.tree_util.tree_map(lambda x: np.asarray(x)[index], tree)


def episode_frames(run_path: Path, episodes: int, seed: int, env_args: dict | None = None) -> list[np.ndarray]:
    """Frames of ``episodes`` episodes played by the unperturbed agent, each up to its end."""
    import jax

    from pizero_ray.agent import episodes as play
    from pizero_ray.storage import runs

    config, _, theta, env, layout, agent = runs.load_run(run_path, env_args)
    if env.render is None:
        raise ConfigError(f"environment {config.env!r} has no renderer")
    record = jax.jit(lambda th, key: play.record_episodes(agent, layout.unravel(th), env, key, episodes))
    trajectory = record(theta, jax.random.PRNGKey(seed))
    dones = np.asarray(trajectory.dones)
    frames = []
    for e in range(episodes):
        frames.append(env.render(_unbatch(trajectory.initial_state, e)))
        for t in range(dones.shape[0]):
            frames.append(env.render(_unbatch(trajectory.states, t, e)))
            if dones[t, e]:
                break
    return frames


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
