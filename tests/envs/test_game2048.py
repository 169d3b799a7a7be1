import jax
import jax.numpy as jnp
import numpy as np
import pytest

from pizero_ray import envs
from pizero_ray.envs import game2048
from pizero_ray.envs.base import random_legal_action

UP, RIGHT, DOWN, LEFT = range(4)


@pytest.fixture(scope="module")
def env():
    return envs.make("2048", horizon=30)


@pytest.fixture(scope="module")
def step(env):
    return jax.jit(env.step)


def with_board(env, rows, step_count=0):
    """A state holding a hand-built board of exponents (rows missing below are empty)."""
    from jumanji.environments.logic.game_2048.utils import can_move

    board = np.zeros((4, 4), np.int32)
    board[: len(rows)] = rows
    board = jnp.asarray(board)
    state, _ = env.reset(jax.random.PRNGKey(0))
    valid = jax.vmap(can_move, (None, 0))(board, jnp.arange(4))
    return game2048.Game2048State(state.game.replace(board=board, action_mask=valid, step_count=jnp.int32(step_count)))


def spawned_cell(before_move_expected, after):
    """The one cell where a new tile (2 or 4) appeared on top of the expected board."""
    diff = np.asarray(after) - np.asarray(before_move_expected)
    cells = np.argwhere(diff != 0)
    assert len(cells) == 1, f"expected exactly one new tile, got board\n{np.asarray(after)}"
    r, c = cells[0]
    assert before_move_expected[r, c] == 0 and after[r, c] in (1, 2)
    return r, c


def test_reset_shapes_and_spec(env):
    state, obs = env.reset(jax.random.PRNGKey(3))
    spec = env.spec
    assert spec == envs.EnvSpec(observation_size=16 + 4 + 1, horizon=30, num_actions=4, action_feature_size=4)
    assert obs.vector.shape == (spec.observation_size,)
    np.testing.assert_array_equal(obs.action_features, np.eye(4))
    assert int((np.asarray(state.game.board) > 0).sum()) == 1  # Jumanji starts with one tile
    board = np.asarray(state.game.board).reshape(-1)
    np.testing.assert_allclose(obs.vector[:16], board / 16)
    np.testing.assert_array_equal(obs.vector[16:20], np.asarray(obs.action_mask, np.float32))
    assert float(obs.vector[-1]) == 0.0


def test_one_hot_tiles():
    env = envs.make("2048", tile_encoding="one_hot")
    state, obs = env.reset(jax.random.PRNGKey(0))
    assert env.spec.observation_size == 16 * 16 + 5 == obs.vector.shape[0]
    cells = np.asarray(obs.vector[:256]).reshape(16, 16)
    np.testing.assert_array_equal(cells.sum(axis=1), 1)
    np.testing.assert_array_equal(cells.argmax(axis=1), np.asarray(state.game.board).reshape(-1))


@pytest.mark.parametrize(
    "row, action, expected_row, reward",
    [
        ([1, 1, 1, 1], LEFT, [2, 2, 0, 0], 8),  # 2 2 2 2 -> 4 4 . .
        ([1, 1, 1, 1], RIGHT, [0, 0, 2, 2], 8),
        ([1, 0, 1, 2], LEFT, [2, 2, 0, 0], 4),  # a merged tile does not merge again in the same move
        ([3, 0, 0, 3], LEFT, [4, 0, 0, 0], 16),
    ],
)
def test_merges_and_their_rewards(env, step, row, action, expected_row, reward):
    state = with_board(env, [row])
    state, obs, got_reward, done = step(state, jnp.int32(action))
    expected = np.zeros((4, 4), np.int32)
    expected[0] = expected_row
    spawned_cell(expected, np.asarray(state.game.board))
    assert float(got_reward) == reward and not bool(done)


def test_vertical_moves_merge_columns(env, step):
    state = with_board(env, [[1, 0, 0, 0], [1, 0, 0, 0], [2, 0, 0, 0], [2, 0, 0, 0]])
    state, _, reward, _ = step(state, jnp.int32(DOWN))
    expected = np.zeros((4, 4), np.int32)
    expected[2:, 0] = [2, 3]
    spawned_cell(expected, np.asarray(state.game.board))
    assert float(reward) == 4 + 8


def test_action_mask_is_the_moves_that_change_the_board(env, step):
    state = with_board(env, [[1, 2, 3, 4]])  # a full top row that cannot merge: only down moves anything
    np.testing.assert_array_equal(np.asarray(state.game.action_mask), [False, False, True, False])
    state, obs = env.reset(jax.random.PRNGKey(1))
    for t in range(8):
        changes = [bool((step(state, jnp.int32(a))[0].game.board != state.game.board).any()) for a in range(4)]
        assert list(np.asarray(obs.action_mask)) == changes
        state, obs, _, _ = step(state, random_legal_action(state.game.action_mask, jax.random.PRNGKey(t)))


def test_invalid_move_is_a_silent_no_op(env, step):
    state = with_board(env, [[1, 2, 3, 4]])
    after, obs, reward, done = step(state, jnp.int32(LEFT))
    np.testing.assert_array_equal(after.game.board, state.game.board)  # no tile appears either
    assert float(reward) == 0.0 and not bool(done)


def test_no_valid_move_ends_the_game(env, step):
    rows = [[0, 3, 4, 5], [6, 7, 8, 9], [3, 4, 5, 6], [6, 7, 8, 9]]
    state, obs, reward, done = step(with_board(env, rows), jnp.int32(LEFT))
    board = np.asarray(state.game.board)
    np.testing.assert_array_equal(board[0, :3], [3, 4, 5])
    assert board[0, 3] in (1, 2)  # the new tile fills the last cell and nothing can merge
    assert bool(done) and not bool(obs.action_mask.any())


def test_horizon_ends_the_episode():
    env = envs.make("2048", horizon=3)
    state, obs = env.reset(jax.random.PRNGKey(0))
    step = jax.jit(env.step)
    dones = []
    for _ in range(3):
        action = jnp.argmax(obs.action_mask)
        state, obs, _, done = step(state, action)
        dones.append(bool(done))
    assert dones == [False, False, True]
    assert float(obs.vector[-1]) == 1.0  # the whole horizon has elapsed


def test_game_score_is_the_sum_of_rewards(env, step):
    state, obs = env.reset(jax.random.PRNGKey(5))
    total, done = 0.0, False
    for t in range(env.spec.horizon):
        action = random_legal_action(state.game.action_mask, jax.random.PRNGKey(t))
        state, obs, reward, step_done = step(state, action)
        total += 0.0 if done else float(reward)
        done = done or bool(step_done)
    assert done and total > 0
    assert total == pytest.approx(float(state.game.score))


def test_highest_tile():
    assert int(game2048.highest_tile(jnp.zeros((4, 4), jnp.int32))) == 0
    assert int(game2048.highest_tile(jnp.array([[1, 11], [3, 0]]))) == 2048


def test_greedy_takes_the_largest_merge_with_lowest_index_ties(env):
    # left and right both merge 2+2 and 4+4 (12); up and down merge nothing: the tie goes to right (1)
    assert int(game2048.greedy_policy(with_board(env, [[1, 1, 2, 2]]))) == RIGHT
    # up and down merge the column of 8s (16 each), left/right the 2s (4): up wins
    state = with_board(env, [[3, 1, 1, 0], [3, 0, 0, 0]])
    np.testing.assert_array_equal(game2048.merge_rewards(state.game.board), [16, 4, 16, 4])
    assert int(game2048.greedy_policy(state)) == UP
    # nothing merges: the first valid move (right; up is invalid for a top row)
    assert int(game2048.greedy_policy(with_board(env, [[1, 2, 0, 0]]))) == RIGHT


def test_references_are_deterministic_and_greedy_beats_random(env):
    initial_states, _ = jax.vmap(env.reset)(jax.random.split(jax.random.PRNGKey(0), 16))
    first = env.references(initial_states, np.zeros(16))
    assert set(first) == {"random_score", "random_highest_tile", "greedy_score", "greedy_highest_tile"}
    assert first == env.references(initial_states, np.zeros(16))
    assert first["greedy_score"] > first["random_score"] > 0
    assert first["random_highest_tile"] >= 8


def test_render_draws_the_board(env):
    state = with_board(env, [[1, 2, 11, 12], [0, 5, 0, 7]])
    image = env.render(jax.tree_util.tree_map(np.asarray, state))
    assert image.dtype == np.uint8 and image.ndim == 3 and image.shape[2] == 3
    assert len(np.unique(image.reshape(-1, 3), axis=0)) > 10  # coloured tiles and text


@pytest.mark.parametrize(
    "args, message",
    [
        ({"horizon": 0}, "2048: horizon must be an integer at least 1, got 0"),
        ({"horizon": -5}, "2048: horizon must be an integer at least 1, got -5"),
        ({"horizon": 2.5}, "2048: horizon must be an integer at least 1, got 2.5"),
        ({"horizon": "200"}, "2048: horizon must be an integer at least 1, got '200'"),
        ({"tile_encoding": "bits"}, "2048: tile_encoding must be one of log2, one_hot, got 'bits'"),
        ({"tile_encoding": None}, "2048: tile_encoding must be one of log2, one_hot, got None"),
        ({"board": 5}, "bad parameters for environment '2048'"),
    ],
)
def test_bad_parameters_are_one_line_errors(args, message):
    with pytest.raises(ValueError) as error:
        envs.make("2048", **args)
    assert message in str(error.value) and "\n" not in str(error.value)


def test_episode_metrics_report_the_highest_tile():
    env = envs.make("2048", horizon=5)
    states, _ = jax.vmap(env.reset)(jax.random.split(jax.random.PRNGKey(0), 3))
    board = states.game.board.at[0, 0, 0].set(7).at[1, 2, 3].set(3)
    metrics = env.episode_metrics(states._replace(game=states.game.replace(board=board)))
    assert list(metrics["highest_tile"][:2]) == [128, 8]


def test_reseed_keeps_the_board_and_redraws_the_next_tile(env):
    state, _ = env.reset(jax.random.PRNGKey(0))
    action = jnp.int32(int(np.argmax(np.asarray(state.game.action_mask))))
    reseeded = [env.reseed(state, jax.random.PRNGKey(k)) for k in range(8)]
    for other in reseeded:
        np.testing.assert_array_equal(other.game.board, state.game.board)
    next_boards = {np.asarray(env.step(other, action)[0].game.board).tobytes() for other in reseeded}
    assert len(next_boards) > 1  # the same move, different new tiles
