"""The protocol check: every registered environment passes it, and each way of breaking the protocol is one line
naming the problem and the environment."""

import jax.numpy as jnp
import pytest

from examples import corridor
from pizero_ray import envs
from pizero_ray.envs.check import check_environment

SMALL = {"sokoban": {"num_levels": 20}}  # fewer levels read: the check is about shapes, not the game


@pytest.mark.parametrize("name", envs.ENV_NAMES)
def test_every_registered_environment_passes_the_check(name):
    env = envs.make(name, **SMALL.get(name, {}))
    assert check_environment(env) is env


def _stepping(env, change):
    """``env`` whose step's return (state, observation, reward, done) goes through ``change``."""
    return env._replace(step=lambda state, action: change(*env.step(state, action)))


def _resetting(env, change):
    """``env`` whose reset's observation goes through ``change``."""
    return env._replace(reset=lambda key: (lambda state, obs: (state, change(obs)))(*env.reset(key)))


def _python_if_step(env):
    def step(state, action):
        if action == corridor.RIGHT:  # Python control flow on a traced value
            return env.step(state, action)
        return env.step(state, action)

    return env._replace(step=step)


BROKEN = {
    "not an Environment": (lambda env: {"reset": env.reset},
                           "the factory must return a pizero_ray.envs.base.Environment, got dict"),
    "reset missing": (lambda env: env._replace(reset=None), "reset must be a function, got NoneType"),
    "step not callable": (lambda env: env._replace(step="step"), "step must be a function, got str"),
    "render not callable": (lambda env: env._replace(render=1), "render must be a function or None, got int"),
    "spec not an EnvSpec": (lambda env: env._replace(spec=tuple(env.spec)),
                            "spec must be a pizero_ray.envs.base.EnvSpec"),
    "spec size a string": (lambda env: env._replace(spec=env.spec._replace(observation_size="17")),
                           "spec.observation_size must be an integer at least 1, got '17'"),
    "spec horizon a float": (lambda env: env._replace(spec=env.spec._replace(horizon=16.0)),
                             "spec.horizon must be an integer at least 1, got 16.0"),
    "spec neither kind": (lambda env: env._replace(spec=env.spec._replace(num_actions=0)),
                          "spec must have num_actions > 0 (discrete) or action_dim > 0 (continuous), not neither"),
    "vector size off the spec": (lambda env: env._replace(spec=env.spec._replace(observation_size=18)),
                                 "reset's observation.vector must be float32[18] (from the spec), got float32[17]"),
    "vector dtype": (lambda env: _resetting(env, lambda o: o._replace(vector=o.vector.astype(jnp.float16))),
                     "reset's observation.vector must be float32[17] (from the spec), got float16[17]"),
    "action features off the spec": (lambda env: env._replace(spec=env.spec._replace(action_feature_size=4)),
                                     "observation.action_features must be float32[2,4] (from the spec), "
                                     "got float32[2,3]"),
    "mask of ints": (lambda env: _resetting(env, lambda o: o._replace(action_mask=o.action_mask.astype(jnp.int32))),
                     "reset's observation.action_mask must be bool[2] (from the spec), got int32[2]"),
    "observation a tuple": (lambda env: _resetting(env, tuple), "reset must return a pizero_ray.envs.base.Observation"),
    "reward not a scalar": (lambda env: _stepping(env, lambda s, o, r, d: (s, o, r[None], d)),
                            "step's reward must be a float scalar (shape ()), got float32[1]"),
    "done not a bool": (lambda env: _stepping(env, lambda s, o, r, d: (s, o, r, d.astype(jnp.float32))),
                        "step's done must be a bool scalar (shape ()), got float32[]"),
    "step returns three": (lambda env: _stepping(env, lambda s, o, r, d: (s, o, r)),
                           "step must return a tuple (state, observation, reward, done), got tuple of 3"),
    "state changes dtype": (lambda env: _stepping(env, lambda s, o, r, d: (s._replace(t=s.t * 1.0), o, r, d)),
                            "step must return a state like reset's"),
    "step not jittable": (_python_if_step, "step is not jittable: Python control flow or NumPy on a traced value"),
    "reset fails": (lambda env: env._replace(reset=lambda key: key + jnp.zeros(3)), "reset failed while tracing"),
}


@pytest.mark.parametrize("case", BROKEN)
def test_a_broken_environment_is_one_line_naming_the_problem(case):
    breaking, problem = BROKEN[case]
    broken = breaking(corridor.make())
    with pytest.raises(ValueError) as raised:
        check_environment(broken, "examples.corridor:make")
    message = str(raised.value)
    assert message.startswith("environment 'examples.corridor:make': ") and len(message.splitlines()) == 1
    assert problem in message


def test_a_continuous_environments_action_bounds_are_checked():
    env = envs.make("flp")
    assert not env.spec.discrete and check_environment(env) is env
    with pytest.raises(ValueError, match="action_low must be below spec.action_high"):
        check_environment(env._replace(spec=env.spec._replace(action_low=1.0)))


def _mask_empty_after(env, steps):
    """``env`` whose mask has no legal action from its ``steps``-th step on (0: from reset)."""
    def emptied(state, observation):
        empty = observation.action_mask & (state.t < steps)
        return observation._replace(action_mask=empty)

    def reset(key):
        state, observation = env.reset(key)
        return state, emptied(state, observation)

    def step(state, action):
        state, observation, reward, done = env.step(state, action)
        return state, emptied(state, observation), reward, done & False  # never ends first

    return env._replace(reset=reset, step=step)


@pytest.mark.parametrize("steps, where", [(0, "reset"), (2, "step 2")])
def test_an_action_mask_with_no_legal_action_is_one_line(steps, where):
    with pytest.raises(ValueError) as raised:
        check_environment(_mask_empty_after(corridor.make(), steps), "mine:make")
    assert str(raised.value) == (f"environment 'mine:make': {where}'s observation.action_mask has no legal action: "
                                 "at least one action must always be legal")


def test_an_environment_that_breaks_only_under_vmap_is_one_line_naming_it():
    import jax
    import numpy as np

    env = corridor.make()

    def step(state, action):  # a host callback without a vmap_method: fine alone, broken in a batch
        state, observation, reward, done = env.step(state, action)
        reward = jax.pure_callback(np.float32, jax.ShapeDtypeStruct((), jnp.float32), reward)
        return state, observation, reward, done

    with pytest.raises(ValueError) as raised:
        check_environment(env._replace(step=step), "mine:make")
    message = str(raised.value)
    assert message.startswith("environment 'mine:make': step under jax.vmap failed while tracing: "
                              "NotImplementedError: vmap is only supported"), message
    assert "\n" not in message
