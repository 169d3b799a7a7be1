"""A run's training state on disk: save it as a checkpoint, restore the newest good one, hash its parameters.

The state is any of the methods' (``ESState``, ``LearnerState``): a NamedTuple
with ``theta``, ``iteration`` and ``carried`` (what else training continues
from: Adam's moments, a replay buffer), and ``with_carried`` to put that back.
Storage never builds a method: ``pizero_ray.methods`` does.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np

from pizero_ray.config import Config
from pizero_ray.storage import checkpoints


def parameter_hash(theta: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(theta, dtype="<f4").tobytes()).hexdigest()


def restore(run_path: Path, state, **resume_options):
    """``state`` with the run's newest good checkpoint restored into it (see ``checkpoints.prepare_resume``).

    Returns (state, the metrics rows kept). Refuses a run dir whose progress
    it cannot continue; never deletes a metrics row.
    """
    import jax.numpy as jnp

    resumed = checkpoints.prepare_resume(run_path, np.asarray(state.theta), state.carried, **resume_options)
    restored = state.with_carried(resumed.carried)._replace(theta=jnp.asarray(resumed.theta),
                                                              iteration=resumed.iteration)
    return restored, resumed.metrics


def save(writer, config: Config, state) -> None:
    """Saves ``state`` as the checkpoint of its iteration."""
    theta = np.asarray(state.theta)
    meta = {"iteration": state.iteration, "seed": config.seed, "config": json.loads(config.to_json()),
            "parameter_hash": parameter_hash(theta)}
    writer.save(state.iteration, theta, state.carried, meta)
