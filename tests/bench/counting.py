"""An independent count of agent steps: environments whose step reports itself to the host."""

import jax
import numpy as np

from pizero_ray import envs


def count_environment_steps(monkeypatch) -> list[int]:
    """Makes ``envs.make``'s environments (discrete actions) count every step they take into the returned list:
    a host callback in ``step``, whose entries sum to the steps taken, under ``vmap`` as outside it. Call
    ``jax.effects_barrier()`` before reading it."""
    steps: list[int] = []
    make = envs.make

    def counting_make(name, **kwargs):
        env = make(name, **kwargs)

        def step(state, action):
            # Under vmap the callback runs once per batch element of its argument, and only of the axes that
            # argument is batched along: the action depends on the member's parameters, so it is batched along
            # every member and episode (the done flag is not: on TSP it depends on the step number alone).
            # A discrete action is one number per step.
            jax.debug.callback(lambda taken: steps.append(int(np.size(taken))), action)
            return env.step(state, action)

        return env._replace(step=step)

    monkeypatch.setattr(envs, "make", counting_make)
    return steps
