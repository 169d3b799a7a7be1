import jax
import jax.numpy as jnp
import numpy as np

from pizero_ray.agent import episodes, make_agent
from pizero_ray.es import population


def test_run_episodes_scores_every_episode(tiny_config, tsp_env):
    theta, layout = population.flat_params(tiny_config, tsp_env)
    agent = make_agent(tiny_config, tsp_env.spec)
    scores = episodes.make_evaluator(agent, tsp_env, layout.unravel, 7)(theta, jax.random.PRNGKey(0))
    assert scores.shape == (7,)
    assert np.all(np.asarray(scores) < -1.0)


def test_recorded_episodes_are_the_scored_ones_and_rewards_stop_at_the_end(tiny_config):
    import envs

    env = envs.make("collect", horizon=6)
    agent = make_agent(tiny_config, env.spec)
    params = agent.init(jax.random.PRNGKey(0))
    key = jax.random.PRNGKey(3)
    scores = jax.jit(lambda p: episodes.run_episodes(agent, p, env, key, 5))(params)
    trajectory = jax.jit(lambda p: episodes.record_episodes(agent, p, env, key, 5))(params)
    np.testing.assert_array_equal(np.asarray(trajectory.scores), np.asarray(scores))
    np.testing.assert_allclose(np.asarray(trajectory.rewards).sum(0), np.asarray(scores), rtol=1e-6)
    dones = np.asarray(trajectory.dones)
    assert dones.shape == (6, 5) and dones[-1].all()
    np.testing.assert_array_equal(np.asarray(episodes.episode_reset_keys(key, 5)),
                                  np.asarray(jax.random.split(jax.random.fold_in(key, 0), 5)))
    assert jnp.issubdtype(trajectory.actions.dtype, jnp.integer)
