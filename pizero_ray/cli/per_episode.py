"""``pizero eval --per-episode FILE``: each episode's score, with what replays the episode.

Episode i of ``--seed S`` starts from the instance that reset key i of
``jax.random.split(jax.random.fold_in(jax.random.PRNGKey(S), 0), N)`` makes
(``agent.episodes.episode_reset_keys``); key i depends on S and i alone (JAX's
partitionable threefry, its default since JAX 0.5), so every run on the same
environment starts episode i from the same instance, and the same seed and
episode count replay the whole evaluation.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from pizero_ray.cli.arguments import UsageError

FORMATS = {".jsonl": "one JSON object a line: episode, seed, score",
           ".npy": "the scores alone, float64, in episode order (the seed is eval's --seed)"}


def checked_path(text: str) -> Path:
    """The file named, if its extension is a format we write; else a one-line error naming it."""
    path = Path(text)
    if path.suffix not in FORMATS:
        raise UsageError(f"--per-episode must end in {' or '.join(FORMATS)}, got {text}")
    return path


def write(path: Path, scores: np.ndarray, seed: int) -> Path:
    """``scores`` (episode order) written whole or not at all: an existing file is replaced, as render's is."""
    scores = np.asarray(scores, dtype=np.float64)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    if path.suffix == ".npy":
        with tmp.open("wb") as file:  # np.save given a path would append .npy to the temporary name
            np.save(file, scores)
    else:
        tmp.write_text("".join(json.dumps({"episode": i, "seed": seed, "score": float(score)}) + "\n"
                               for i, score in enumerate(scores)))
    tmp.replace(path)
    return path
