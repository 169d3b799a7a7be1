"""Every environment keeps the protocol: batched reset/step compile once, shapes follow the spec."""

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from pizero_ray import envs
from pizero_ray.envs.base import (
    centred_window,
    fresh_initial_states,
    mean_reference_metrics,
    play_policy,
    random_legal_action,
    reference_player,
    require,
    require_bool,
    require_choice,
    require_int,
    require_path,
)

# Short episodes where the horizon is a parameter: these tests are about the protocol, not the game.
SMALL = {"2048": {"horizon": 8}, "pacman": {"horizon": 8}, "pacman-po": {"horizon": 8}, "sokoban": {"num_levels": 20}}
BATCH = 4
# A reference solver each environment's references must report (the scale a reader judges a score on).
REFERENCE_KEYS = {
    "tsp": {"nearest_neighbour_tour_length", "optimal_tour_length"},
    "collect": {"greedy_score", "random_score", "optimal_score"},
    "flp": {"random_score"},
    "flp-mean": {"random_score"},
    "2048": {"random_score", "greedy_score"},
    "pacman": {"random_score"},
    "pacman-po": {"random_score"},
    "sokoban": {"random_goals_covered", "random_solved_fraction"},
}


def _legal_actions(env, obs, t):
    if env.spec.discrete:
        # the first legal action from a rotating start, so that consecutive steps differ
        order = (jnp.arange(env.spec.num_actions) + t) % env.spec.num_actions
        return order[jnp.argmax(obs.action_mask[:, order], axis=-1)].astype(jnp.int32)
    return jnp.full((BATCH, env.spec.action_dim), 0.25 + 0.1 * t, jnp.float32)


@pytest.mark.parametrize("name", envs.ENV_NAMES)
def test_batched_reset_and_step_compile_once_and_follow_the_spec(name):
    env = envs.make(name, **SMALL.get(name, {}))
    spec = env.spec
    chex.clear_trace_counter()  # chex counts traces per function source: each environment starts at zero

    @jax.jit
    @chex.assert_max_traces(n=1)
    def batched_step(states, actions):
        return jax.vmap(env.step)(states, actions)

    states, obs = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.PRNGKey(0), BATCH))
    for t in range(3):
        states, obs, reward, done = batched_step(states, _legal_actions(env, obs, t))
    assert obs.vector.shape == (BATCH, spec.observation_size) and obs.vector.dtype == jnp.float32
    assert reward.shape == done.shape == (BATCH,) and done.dtype == jnp.bool_
    assert np.isfinite(np.asarray(reward)).all()
    if spec.discrete:
        assert obs.action_features.shape == (BATCH, spec.num_actions, spec.action_feature_size)
        assert obs.action_mask.shape == (BATCH, spec.num_actions) and obs.action_mask.dtype == jnp.bool_
    else:
        assert spec.action_dim > 0 and spec.num_actions == 0


@pytest.mark.parametrize("name", envs.ENV_NAMES)
def test_every_environment_renders_and_has_references(name):
    env = envs.make(name, **SMALL.get(name, {}))
    state, _ = env.reset(jax.random.PRNGKey(1))
    image = env.render(jax.tree_util.tree_map(np.asarray, state))
    assert image.dtype == np.uint8 and image.ndim == 3 and image.shape[2] == 3 and min(image.shape[:2]) >= 64
    states, _ = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.PRNGKey(2), BATCH))
    references = env.references(states, np.zeros(BATCH, np.float32))
    assert isinstance(references, dict) and REFERENCE_KEYS[name] <= set(references), references
    assert all(isinstance(value, float) and np.isfinite(value) for value in references.values()), references


# ---------------------------------------------------------------- the shared reference player


def _counting_step(state, action):
    """A tiny deterministic environment: the state counts steps and knows when it ends; the reward is the action."""
    count, done_at = state
    count = count + 1
    return (count, done_at), 100 * count, action.astype(jnp.float32), count >= done_at


def _start(done_at):
    return jnp.int32(0), jnp.int32(done_at)


def test_play_policy_ignores_rewards_after_done_and_keeps_the_final_state():
    # rewards 1, 10, 100, ... (10^t): the total shows which steps counted
    playout = play_policy(_counting_step, lambda state, observation, t: 10**t, _start(3), horizon=5)
    assert float(playout.total_reward) == 1 + 10 + 100  # not 11111: the steps after done pay nothing
    assert int(playout.length) == 3
    assert int(playout.final_state[0]) == 3  # steps 4 and 5 were taken but the state stopped where it ended


def test_play_policy_without_done_plays_to_the_horizon():
    playout = play_policy(_counting_step, lambda state, observation, t: 10**t, _start(99), horizon=4)
    assert float(playout.total_reward) == 1111 and int(playout.length) == 4 and int(playout.final_state[0]) == 4


def test_play_policy_passes_the_last_observation_and_the_step_index():
    def policy(state, observation, t):
        return observation + t  # 7 + 0, then 100 + 1, then 200 + 2

    playout = play_policy(_counting_step, policy, _start(99), horizon=3, initial_observation=jnp.int32(7))
    assert float(playout.total_reward) == 7 + 101 + 202

    def state_only(state, observation, t):
        assert observation is None  # no initial observation: the policy reads the state only
        return state[0] + t

    assert float(play_policy(_counting_step, state_only, _start(99), horizon=3).total_reward) == 0 + 2 + 4


def test_play_policy_is_jittable_and_vmappable():
    def play(done_at):
        return play_policy(_counting_step, lambda state, observation, t: 10**t, _start(done_at), horizon=4)

    playouts = jax.jit(jax.vmap(play))(jnp.array([1, 2, 3, 4, 9]))
    np.testing.assert_array_equal(playouts.total_reward, [1, 11, 111, 1111, 1111])
    np.testing.assert_array_equal(playouts.length, [1, 2, 3, 4, 4])
    np.testing.assert_array_equal(playouts.final_state[0], [1, 2, 3, 4, 4])


def test_random_legal_action_draws_only_legal_actions_and_all_of_them():
    mask = jnp.array([False, True, False, True, True])
    keys = jax.random.split(jax.random.PRNGKey(0), 300)
    draws = jax.jit(jax.vmap(random_legal_action, in_axes=(None, 0)))(mask, keys)
    assert draws.dtype == jnp.int32 and set(np.asarray(draws).tolist()) == {1, 3, 4}
    assert int(random_legal_action(jnp.array([False, False, True]), jax.random.PRNGKey(5))) == 2


def _keyed_reference_player():
    """On the counting environment: reward = a number drawn from the key ``reference_player`` gives at each step."""
    def policy(state, observation, key):
        return jax.random.randint(key, (), 0, 1000)

    return reference_player(_counting_step, policy, horizon=4, summarise=lambda p: (p.total_reward, p.length))


def test_reference_player_gives_the_policy_a_key_per_step_folded_from_the_episode_key():
    keys = jax.random.split(jax.random.PRNGKey(3), 2)
    rewards, lengths = _keyed_reference_player()((jnp.zeros(2, jnp.int32), jnp.array([2, 9])), keys)
    expected = [sum(int(jax.random.randint(jax.random.fold_in(key, t), (), 0, 1000)) for t in range(steps))
                for key, steps in zip(keys, (2, 4))]
    np.testing.assert_array_equal(rewards, expected)
    np.testing.assert_array_equal(lengths, [2, 4])


def test_reference_player_passes_the_observation_from_the_initial_state():
    def policy(state, observation, key):
        return observation  # 100 * steps taken, and 5 before the first

    player = reference_player(_counting_step, policy, 3, lambda p: (p.total_reward,), lambda state: state[0] + 5)
    (rewards,) = player((jnp.zeros(1, jnp.int32), jnp.array([9])), jax.random.split(jax.random.PRNGKey(0), 1))
    assert float(rewards[0]) == 5 + 100 + 200


def test_mean_reference_metrics_names_player_and_metric_and_gives_every_player_the_same_keys():
    player = _keyed_reference_player()
    states = (jnp.zeros(3, jnp.int32), jnp.array([1, 3, 9]))
    means = mean_reference_metrics({"a": player, "b": player}, ("score", "length"), states, seed=11)
    assert list(means) == ["a_score", "a_length", "b_score", "b_length"]
    rewards, lengths = player(states, jax.random.split(jax.random.PRNGKey(11), 3))
    assert means["a_score"] == means["b_score"] == float(np.mean(np.asarray(rewards)))
    assert means["a_length"] == means["b_length"] == (1 + 3 + 4) / 3
    assert all(type(value) is float for value in means.values())


def test_fresh_initial_states_are_the_batched_resets_of_keys_split_from_the_seed():
    env = envs.make("collect")
    states = fresh_initial_states(env, 3, seed=4)
    one, _ = env.reset(jax.random.split(jax.random.PRNGKey(4), 3)[2])
    np.testing.assert_array_equal(states.coins[2], one.coins)


# ---------------------------------------------------------------- checking parameters


@pytest.mark.parametrize(
    "check, message",
    [
        (lambda: require_int("e", "n", 0, 1), "e: n must be an integer at least 1, got 0"),
        (lambda: require_int("e", "n", 9, 1, 8), "e: n must be an integer in 1..8, got 9"),
        (lambda: require_int("e", "n", True, 0), "e: n must be an integer at least 0, got True"),
        (lambda: require_int("e", "n", 3.0, 1), "e: n must be an integer at least 1, got 3.0"),
        (lambda: require_int("e", "n", 4, 1, odd=True), "e: n must be an odd integer at least 1, got 4"),
        (lambda: require_int("e", "n", 5, 1, 3, odd=True), "e: n must be an odd integer in 1..3, got 5"),
        (lambda: require_bool("e", "b", "true"), "e: b must be true or false, got 'true'"),
        (lambda: require_bool("e", "b", 0), "e: b must be true or false, got 0"),
        (lambda: require_choice("e", "c", "z", ("x", "y")), "e: c must be one of x, y, got 'z'"),
        (lambda: require_choice("e", "c", True, (1, 2)), "e: c must be one of 1, 2, got True"),
        (lambda: require_choice("e", "c", ["x"], ("x", "y")), "e: c must be one of x, y, got ['x']"),
        (lambda: require_path("e", "p", ""), "e: p must be a file or directory path, got ''"),
        (lambda: require_path("e", "p", None), "e: p must be a file or directory path, got None"),
        (lambda: require(False, "e", "p", "a\nb", "fine"), "e: p must be fine, got 'a\\nb'"),
    ],
)
def test_parameter_checks_raise_one_line_naming_environment_parameter_and_value(check, message):
    with pytest.raises(ValueError) as error:
        check()
    assert str(error.value) == message


def test_parameter_checks_pass_good_values_and_keep_odd_values_on_one_short_line():
    require_int("e", "n", 1, 1)
    require_int("e", "n", 8, 1, 8)
    require_int("e", "n", 3, 1, odd=True)
    require_bool("e", "b", False)
    require_choice("e", "c", "y", ("x", "y"))
    require_path("e", "p", "levels/")
    with pytest.raises(ValueError) as error:
        require_int("e", "n", np.zeros((20, 20)), 1)  # its repr spans 20 lines
    assert "\n" not in str(error.value) and len(str(error.value)) < 150


def test_centred_window_puts_the_centre_in_the_middle_and_fills_off_the_plane():
    plane = jnp.arange(16).reshape(4, 4)
    window = jax.jit(centred_window, static_argnums=(2,))(plane, jnp.array([0, 3]), 1, -1)
    np.testing.assert_array_equal(window, [[-1, -1, -1], [2, 3, -1], [6, 7, -1]])
    middle = centred_window(plane, jnp.array([2, 1]), 1, -1)
    np.testing.assert_array_equal(middle, [[4, 5, 6], [8, 9, 10], [12, 13, 14]])
