"""The best placement of the facilities that ignores the instance, as a yardstick for FLP agents.

Fits one fixed placement (Nelder-Mead, 20 random starts) on 1,000 instances
(key 1) and scores it on the 1,000 that ``pizero eval --episodes 1000 --seed 0``
plays (key 0), for both objectives. An agent that scores below it has not
learned to use the instance::

    JAX_PLATFORMS=cpu python scripts/flp_fixed_placement.py
"""

from __future__ import annotations

import sys
from pathlib import Path

import jax
import numpy as np
from scipy.optimize import minimize

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import envs  # noqa: E402
from pizero_ray.agent.episodes import episode_reset_keys  # noqa: E402

STARTS = 20


def clients(name: str, key: int, episodes: int = 1000) -> np.ndarray:
    env = envs.make(name)
    states, _ = jax.vmap(env.reset)(episode_reset_keys(jax.random.PRNGKey(key), episodes))
    return np.asarray(states.clients)


def score(flat_placement: np.ndarray, instances: np.ndarray, aggregate) -> float:
    """Mean objective (a cost: lower is better) of one placement over [I, n, 2] instances."""
    facilities = flat_placement.reshape(-1, 2)
    distances = np.linalg.norm(instances[:, :, None, :] - facilities[None, None], axis=-1).min(-1)
    return float(aggregate(distances, axis=1).mean())


def main() -> None:
    for name, aggregate in (("flp", np.max), ("flp-mean", np.mean)):
        fit, held_out = clients(name, 1), clients(name, 0)
        m = envs.make(name).spec.horizon  # one facility per step
        rng = np.random.default_rng(0)
        best = min((minimize(score, rng.uniform(0, 1, 2 * m), args=(fit, aggregate), method="Nelder-Mead",
                             options=dict(maxiter=4000, xatol=1e-5, fatol=1e-7)) for _ in range(STARTS)),
                   key=lambda result: result.fun)
        placement = np.clip(best.x, 0, 1).reshape(m, 2).round(3).tolist()
        print(f"{name}: fitted {-best.fun:.4f}, held out {-score(best.x, held_out, aggregate):.4f}, at {placement}")


if __name__ == "__main__":
    main()
