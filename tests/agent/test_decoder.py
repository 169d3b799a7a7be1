import itertools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from pizero_ray.agent import decoder, make_agent
from pizero_ray.agent.planner import PlanResult
from pizero_ray.config import DECODER_INPUTS, build_config
from pizero_ray.envs.base import EnvSpec, Observation

K, LATENT = 3, 5
PLAN = PlanResult(jnp.array([2, 0]), jnp.array([[0.2, 0.3, 0.5], [1.0, 0.0, 0.0]]), jnp.array([0.7, -1.5]),
                  jnp.array([[0.1, -0.2, 0.4], [0.9, 0.0, 0.0]]))


@pytest.mark.parametrize("inputs", [combo for n in range(1, len(DECODER_INPUTS) + 1)
                                    for combo in itertools.combinations(DECODER_INPUTS, n)])
def test_the_context_has_the_size_it_declares_and_holds_what_it_names(inputs):
    latent = jnp.arange(2 * LATENT, dtype=jnp.float32).reshape(2, LATENT)
    ctx = decoder.context(latent, PLAN, inputs=inputs, num_abstract_actions=K)
    assert ctx.shape == (2, decoder.context_size(inputs, LATENT, K))
    if inputs == ("value",):
        np.testing.assert_array_equal(np.asarray(ctx[:, 0]), np.asarray(PLAN.root_value))
    if inputs == ("qvalues",):
        np.testing.assert_array_equal(np.asarray(ctx), np.asarray(PLAN.root_qvalues))
    if inputs[0] == "action":
        np.testing.assert_array_equal(np.asarray(ctx[:, :K]), [[0, 0, 1], [1, 0, 0]])


def test_pointer_scores_follow_the_actions_when_they_are_reordered():
    # One network scores every candidate from its own features: permuting the
    # candidates permutes the scores (what lets one decoder serve any instance).
    params = decoder.pointer_init(jax.random.PRNGKey(0), context_size=4, feature_size=3, hidden_size=8)
    ctx = jax.random.normal(jax.random.PRNGKey(1), (2, 4))
    features = jax.random.normal(jax.random.PRNGKey(2), (2, 6, 3))
    order = np.array([4, 1, 5, 0, 3, 2])
    scores = decoder.pointer_scores(params, ctx, features)
    np.testing.assert_allclose(decoder.pointer_scores(params, ctx, features[:, order]), scores[:, order], rtol=1e-6)


def test_argmax_picks_the_best_legal_action():
    scores = jnp.array([[3.0, 1.0, 2.0], [0.0, 5.0, 4.0]])
    mask = jnp.array([[False, True, True], [True, True, True]])
    action = decoder.select_discrete(scores, mask, jax.random.PRNGKey(0), sample=False, noise=1.0)
    assert list(np.asarray(action)) == [2, 1]


def test_sampled_actions_respect_the_mask(tsp_env):
    agent = make_agent(build_config("tiny", action_selection="sample", action_noise=5.0), tsp_env.spec)
    params = agent.init(jax.random.PRNGKey(0))
    _, obs = jax.vmap(tsp_env.reset)(jax.random.split(jax.random.PRNGKey(0), 64))
    obs = obs._replace(action_mask=obs.action_mask.at[:, ::2].set(False))
    action, _, _ = jax.jit(agent.act)(params, agent.initial_memory(64), obs, jax.random.PRNGKey(0))
    assert np.all(np.asarray(action) % 2 == 1)
    assert len(set(np.asarray(action).tolist())) > 1  # sampling, not argmax


def test_the_flat_decoder_has_an_output_per_action_index(tsp_env):
    config = build_config("tiny", decoder="flat")
    params = make_agent(config, tsp_env.spec).init(jax.random.PRNGKey(0))
    assert params["decoder"]["layer1"]["w"].shape[-1] == tsp_env.spec.num_actions


def test_continuous_actions_stay_in_bounds():
    spec = EnvSpec(observation_size=6, horizon=3, num_actions=0, action_feature_size=0, action_dim=2,
                   action_low=-1.0, action_high=2.0)
    agent = make_agent(build_config("tiny", action_selection="sample", action_noise=3.0), spec)
    params = agent.init(jax.random.PRNGKey(0))
    vector = jax.random.normal(jax.random.PRNGKey(1), (16, 6))
    obs = Observation(vector, jnp.zeros((16, 0, 0)), jnp.zeros((16, 0), bool))
    action, _, _ = jax.jit(agent.act)(params, agent.initial_memory(16), obs, jax.random.PRNGKey(2))  # one compile
    assert action.shape == (16, 2)
    assert np.all((np.asarray(action) >= -1.0) & (np.asarray(action) <= 2.0))
    assert len({tuple(row) for row in np.asarray(action).round(4)}) > 1
