"""How much an FLP agent's placements use the instance in front of it.

Plays a run's unperturbed agent on the instances ``pizero eval RUN --episodes
1000 --seed 0`` plays and prints, as JSON:

* ``agent``: its mean score (what ``pizero eval`` reports);
* ``agent_average_placement``: the score of one fixed placement, each
  facility at the mean of where the agent put it over all instances. An agent
  that ignores the clients scores this; one that uses them beats it;
* ``spread``: per facility, the root mean square distance of its placements
  from that mean (0 for an agent that ignores the instance). For scale: a
  uniform point in the unit square lies 0.41 from the centre in that sense.

    JAX_PLATFORMS=cpu python scripts/flp_instance_use.py RUN [--episodes 1000] [--seed 0]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import jax
import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from pizero_ray import methods  # noqa: E402
from pizero_ray.agent import episodes as play  # noqa: E402
from pizero_ray.envs import flp  # noqa: E402


def placement_score(facilities: np.ndarray, clients: np.ndarray, objective: str) -> np.ndarray:
    """[I] scores (the environment's: minus ``flp.cost``) of placements [I, m, 2] or one placement [m, 2]
    on instances [I, n, 2]."""
    facilities = np.broadcast_to(facilities, (clients.shape[0],) + facilities.shape[-2:])
    return -np.asarray(jax.vmap(lambda c, f: flp.cost(c, f, objective))(clients, facilities))


def instance_use(run: Path, episodes: int, seed: int) -> dict:
    config, iteration, theta, env, layout, agent = methods.load_run(run)
    evaluator = play.make_scorer(agent, env, layout.unravel, episodes, final_states=True)
    scores, final_states = evaluator(theta, jax.random.PRNGKey(seed))
    objective = "max" if config.env == "flp" else "mean"
    summary = summarise_placements(np.asarray(scores), np.asarray(final_states.clients),
                                   np.asarray(final_states.facilities), objective)
    return {"run": str(run), "env": config.env, "planner": config.planner, "iteration": iteration,
            "episodes": episodes, "seed": seed, **summary}


def summarise_placements(scores: np.ndarray, clients: np.ndarray, facilities: np.ndarray, objective: str) -> dict:
    """The agent's mean score beside its average placement's, and each facility's spread, over [I] instances."""
    average = facilities.mean(0)
    spread = np.sqrt(((facilities - average) ** 2).sum(-1).mean(0))
    return {
        "agent": float(np.mean(scores)),
        "agent_average_placement": float(placement_score(average, clients, objective).mean()),
        "average_placement": average.round(3).tolist(),
        "spread": spread.round(4).tolist(),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path)
    parser.add_argument("--episodes", type=int, default=1000)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    print(json.dumps(instance_use(args.run, args.episodes, args.seed), indent=1))


if __name__ == "__main__":
    main()
