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

from pizero_ray.config import Config, ConfigError, differing_settings
from pizero_ray.storage import checkpoints


def parameter_hash(theta: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(theta, dtype="<f4").tobytes()).hexdigest()


def check_same_config(run_path: Path, config: Config) -> None:
    """Refuses, in one line naming each differing setting, to continue a run under another configuration.

    The newest checkpoint's saved config is the truth: a config.json edited, or
    replaced, since would otherwise train the run's later iterations under
    other settings while its checkpoints still name the first. Settings that
    change only how the rollout compiles (``COMPILE_ONLY_SETTINGS``) may
    change, as may everything outside the config (budget, evaluation, workers).
    """
    meta = checkpoints.newest_meta(run_path)
    if meta is None or "config" not in meta:
        return
    try:
        saved = Config.from_dict(meta["config"])
    except (ConfigError, TypeError) as error:
        raise ConfigError(f"run dir {run_path}: the config saved with checkpoint {meta.get('iteration')} cannot be "
                          f"read: {error}") from None
    differing = differing_settings(saved, config)
    if differing:
        changes = ", ".join(f"{name} {getattr(saved, name)!r} (now {getattr(config, name)!r})" for name in differing)
        raise ConfigError(f"run dir {run_path} was trained with {changes} up to its checkpoint of iteration "
                          f"{meta['iteration']}: a run keeps one configuration; put config.json back as it was, "
                          "or train a new run (--init-from keeps the parameters)")


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
