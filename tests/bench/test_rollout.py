"""The project's rollout as the bench times it: the agent steps it reports are the steps the environment took."""

import jax
import pytest

from pizero_ray.bench import rollout
from pizero_ray.config import build_config
from tests.bench.counting import count_environment_steps


@pytest.mark.parametrize("max_devices, devices", [(None, 2), (1, 1)])  # the test process has 2 CPU devices
def test_agent_steps_are_the_environment_steps_of_one_iteration(monkeypatch, max_devices, devices):
    steps = count_environment_steps(monkeypatch)
    config = build_config("tiny", population=4, chunk_size=2)
    run = rollout.compile_rollout(config, max_devices)  # compiles, and plays a warm-up iteration
    jax.effects_barrier()
    steps.clear()
    run.one_iteration(1)
    jax.effects_barrier()
    assert sum(steps) == run.agent_steps > 0
    assert run.devices == devices
