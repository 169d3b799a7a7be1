"""The plan ablation: what a trained agent's plan is worth, from the agent itself. An agent whose decoder cannot
read the plan shows exactly nothing; one whose decoder reads only the abstract action shows its actions move."""

import jax
import numpy as np
import pytest

from pizero_ray.agent import ablate_plan, episodes, make_agent
from pizero_ray.agent.planner import PlanResult
from pizero_ray.config import build_config
from pizero_ray.es.population import flat_params

EPISODES = 8


def _plan_use(inputs, tsp_env, ablation="shuffled"):
    """(intact scores, ablated scores, share of actions changed) of an untrained tiny agent on TSP."""
    config = build_config("tiny", decoder_inputs=inputs)
    theta, layout = flat_params(config, tsp_env)
    watching = make_agent(config, tsp_env.spec, watch=ablation)
    ablated = make_agent(config, tsp_env.spec, plan_ablation=ablation)
    key = jax.random.PRNGKey(3)
    intact, changed = episodes.make_plan_use_scorer(watching, tsp_env, layout.unravel, EPISODES)(theta, key)
    ablated_scores = episodes.make_scorer(ablated, tsp_env, layout.unravel, EPISODES)(theta, key)
    return np.asarray(intact), np.asarray(ablated_scores), float(changed)


def test_a_decoder_that_reads_only_the_abstract_state_shows_exactly_nothing(tsp_env):
    intact, ablated, changed = _plan_use(("state",), tsp_env)
    assert changed == 0.0
    np.testing.assert_array_equal(intact, ablated)


def test_a_decoder_that_reads_only_the_abstract_action_shows_its_actions_move(tsp_env):
    intact, ablated, changed = _plan_use(("action",), tsp_env)
    assert 0.0 < changed <= 1.0
    assert not np.array_equal(intact, ablated)


def test_the_watching_agent_plays_the_intact_agents_episodes(tsp_env):
    config = build_config("tiny")
    theta, layout = flat_params(config, tsp_env)
    key = jax.random.PRNGKey(5)
    plain = episodes.make_scorer(make_agent(config, tsp_env.spec), tsp_env, layout.unravel, EPISODES)(theta, key)
    watching = make_agent(config, tsp_env.spec, watch="zeroed")
    watched, _ = episodes.make_plan_use_scorer(watching, tsp_env, layout.unravel, EPISODES)(theta, key)
    np.testing.assert_allclose(np.asarray(watched), np.asarray(plain), rtol=1e-6)


def test_shuffled_hands_each_episode_the_next_ones_plan_and_zeroed_zeros():
    plan = PlanResult(np.array([1, 2, 3]), np.eye(3), np.array([0.1, 0.2, 0.3]))
    shuffled = ablate_plan(plan, "shuffled")
    assert list(np.asarray(shuffled.abstract_action)) == [3, 1, 2]
    np.testing.assert_array_equal(np.asarray(shuffled.visit_probs), np.roll(np.eye(3), 1, axis=0))
    zeroed = ablate_plan(plan, "zeroed")
    assert not np.asarray(zeroed.visit_probs).any() and not np.asarray(zeroed.abstract_action).any()


def test_an_agent_without_a_planner_has_no_plan_to_ablate(tsp_env):
    with pytest.raises(ValueError, match="no plan to ablate"):
        make_agent(build_config("tiny", planner="none"), tsp_env.spec, plan_ablation="shuffled")
