"""The replay buffer: a ring of whole episodes, and targets that are absorbing past an episode's end."""

import jax
import jax.numpy as jnp
import numpy as np

from pizero_ray.baselines.replay import Episodes, replay_add, replay_init, replay_sample, returns_to_go
from pizero_ray.envs.base import Observation


def episodes(first_id: int, batch: int, horizon: int = 4, lengths=None) -> Episodes:
    """Episodes whose observation vector holds (episode id, step); rewards 1, 2, ...; ``lengths`` steps valid."""
    lengths = np.full(batch, horizon) if lengths is None else np.asarray(lengths)
    ids = np.arange(first_id, first_id + batch, dtype=np.float32)[:, None].repeat(horizon, 1)
    steps = np.arange(horizon, dtype=np.float32)[None].repeat(batch, 0)
    valid = steps < lengths[:, None]
    actions = 3
    observation = Observation(jnp.stack([ids, steps], -1), jnp.zeros((batch, horizon, actions, 1)),
                              jnp.ones((batch, horizon, actions), bool))
    policy = jax.nn.one_hot(np.arange(batch * horizon).reshape(batch, horizon) % actions, actions)
    reward = np.where(valid, steps + 1.0, 0.0).astype(np.float32)
    return Episodes(observation, jnp.asarray(steps, jnp.int32) % actions, policy, jnp.asarray(reward),
                    jnp.asarray(valid))


def test_returns_to_go_sum_the_rewards_from_each_step_to_the_end():
    np.testing.assert_allclose(returns_to_go(jnp.asarray([[1.0, 2.0, 3.0, 0.0]])), [[6.0, 5.0, 3.0, 0.0]])


def test_the_ring_keeps_the_newest_episodes():
    replay = replay_init(episodes(0, 1), capacity=5)
    assert int(replay.filled) == 0
    replay = replay_add(replay, episodes(0, 3))
    replay = replay_add(replay, episodes(3, 3))  # six into five slots: episode 0 is overwritten by episode 5
    assert int(replay.filled) == 5 and int(replay.cursor) == 1
    held = sorted(np.asarray(replay.episodes.observation.vector[:, 0, 0]).astype(int).tolist())
    assert held == [1, 2, 3, 4, 5]


def test_samples_stay_inside_episodes_and_targets_are_absorbing_past_the_end():
    replay = replay_add(replay_init(episodes(0, 1), capacity=4), episodes(0, 4, lengths=[4, 2, 3, 1]))
    batch = replay_sample(replay, jax.random.PRNGKey(0), batch_size=256, unroll=2)
    ids = np.asarray(batch.observation.vector[:, 0]).astype(int)
    t = np.asarray(batch.observation.vector[:, 1]).astype(int)
    lengths = np.array([4, 2, 3, 1])[ids]
    assert np.all(t < lengths)  # never a position past the end
    assert set(ids.tolist()) == {0, 1, 2, 3}
    for k in range(3):
        inside = t + k < lengths
        np.testing.assert_array_equal(np.asarray(batch.policy_valid[:, k]), inside)
        # the Monte Carlo return from t + k: the rewards t+k+1, ..., length; 0 past the end
        expected = np.where(inside, (lengths * (lengths + 1) - (t + k) * (t + k + 1)) / 2, 0.0)
        np.testing.assert_allclose(np.asarray(batch.value[:, k]), expected)
    for k in range(2):
        inside = t + k < lengths
        np.testing.assert_allclose(np.asarray(batch.reward[:, k]), np.where(inside, t + k + 1.0, 0.0))
