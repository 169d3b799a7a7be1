import jax
import jax.numpy as jnp
import numpy as np

from pizero_ray.agent import episodes, make_agent
from pizero_ray.es import population


def test_run_episodes_scores_every_episode(tiny_config, tsp_env):
    theta, layout = population.flat_params(tiny_config, tsp_env)
    agent = make_agent(tiny_config, tsp_env.spec)
    scores = episodes.make_scorer(agent, tsp_env, layout.unravel, 7)(theta, jax.random.PRNGKey(0))
    assert scores.shape == (7,)
    assert np.all(np.asarray(scores) < -1.0)


def test_recorded_episodes_are_the_scored_ones_and_rewards_stop_at_the_end(tiny_config):
    from pizero_ray import envs

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


def test_scoring_stops_once_every_episode_ended_with_the_scans_scores_and_final_states(tiny_config):
    from pizero_ray import envs

    game = envs.make("2048", horizon=400)  # a random-ish player ends every game long before 400 moves
    steps_taken = []

    def counted_step(state, action):
        jax.debug.callback(lambda: steps_taken.append(1))
        return game.step(state, action)

    env = game._replace(step=counted_step)
    agent = make_agent(tiny_config, env.spec)
    theta, layout = population.flat_params(tiny_config, env)
    key = jax.random.PRNGKey(5)
    scores, final_states = episodes.make_scorer(agent, env, layout.unravel, 6, final_states=True)(theta, key)
    jax.effects_barrier()
    played = len(steps_taken)
    trajectory = jax.jit(lambda p: episodes.record_episodes(agent, p, env, key, 6))(layout.unravel(theta))

    np.testing.assert_array_equal(np.asarray(scores), np.asarray(trajectory.scores))
    for final, recorded in zip(jax.tree.leaves(final_states), jax.tree.leaves(trajectory.states)):
        np.testing.assert_array_equal(np.asarray(final), np.asarray(recorded)[-1])  # kept from each game's end
    dones = np.asarray(trajectory.dones)
    lengths = 1 + np.argmax(dones, axis=0)  # the step each game ended on
    assert dones[-1].all() and lengths.max() < 400
    assert played == lengths.max()  # the batch of games was stepped until its longest one ended, no further
    for leaf in map(np.asarray, jax.tree.leaves(trajectory.states)):
        np.testing.assert_array_equal(leaf[-1], leaf[lengths - 1, np.arange(6)])  # a finished game's state stays
