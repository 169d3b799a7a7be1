import jax
import jax.numpy as jnp
import numpy as np
import pytest

from pizero_ray import envs
from pizero_ray.envs import pacman
from pizero_ray.envs.base import random_legal_action

UP, LEFT, DOWN, RIGHT, NO_OP = range(5)  # in the maze as printed (Jumanji's docs swap the names of 1 and 3)
START = (23, 13)  # the player's (row, col) at reset
WALL, PELLET, POWER, GHOST = range(4)  # window planes


@pytest.fixture(scope="module")
def full_env():
    return envs.make("pacman", horizon=64)


@pytest.fixture(scope="module")
def po_env():
    return envs.make("pacman-po", horizon=64)


@pytest.fixture(scope="module")
def full_step(full_env):
    return jax.jit(full_env.step)


@pytest.fixture(scope="module")
def maze():
    from jumanji.environments.routing.pac_man.constants import DEFAULT_MAZE
    from jumanji.environments.routing.pac_man.generator import AsciiGenerator

    return pacman.maze_from(AsciiGenerator(DEFAULT_MAZE))


@pytest.fixture(scope="module")
def initial(full_env):
    return full_env.reset(jax.random.PRNGKey(0))[0]


def placed(state, player=None, ghosts=None):
    """The state with the player and/or ghosts moved to (row, col) cells."""
    from jumanji.environments.routing.pac_man.types import Position

    game = state.game
    if player is not None:
        game = game.replace(player_locations=Position(x=jnp.int32(player[0]), y=jnp.int32(player[1])))
    if ghosts is not None:
        game = game.replace(ghost_locations=jnp.array([[c, r] for r, c in ghosts], jnp.int32))  # Jumanji: (col, row)
    return pacman.PacManState(game)


FAR_GHOSTS = [(29, 1), (29, 2), (29, 3), (29, 4)]


def expected_walls(centre, size):
    """Walls of the window from the ASCII maze itself: 'X' or outside the maze."""
    from jumanji.environments.routing.pac_man.constants import DEFAULT_MAZE

    half = size // 2
    rows, cols = len(DEFAULT_MAZE), len(DEFAULT_MAZE[0])
    out = np.ones((size, size), bool)
    for i in range(size):
        for j in range(size):
            r, c = centre[0] - half + i, centre[1] - half + j
            out[i, j] = not (0 <= r < rows and 0 <= c < cols) or DEFAULT_MAZE[r][c] == "X"
    return out


def test_specs_and_shapes(full_env, po_env):
    for env, size in ((full_env, 85), (po_env, 4 * 25 + 4), (envs.make("pacman-po", window_size=7), 4 * 49 + 4)):
        state, obs = env.reset(jax.random.PRNGKey(0))
        assert env.spec == envs.EnvSpec(size, env.spec.horizon, 5, 5)
        assert obs.vector.shape == (size,) and obs.vector.dtype == jnp.float32
        np.testing.assert_array_equal(obs.action_features, np.eye(5))
        np.testing.assert_array_equal(obs.action_mask, [False, True, False, True, False])  # walls above and below
    assert envs.make("pacman").spec.horizon == 128


def test_moves_and_the_first_pellet(full_env, full_step, initial):
    assert tuple(np.asarray(pacman.player_cell(initial.game))) == START
    for action, cell in ((LEFT, (23, 12)), (RIGHT, (23, 14)), (UP, START), (NO_OP, START)):
        state, obs, reward, done = full_step(initial, jnp.int32(action))
        assert tuple(np.asarray(pacman.player_cell(state.game))) == cell  # into a wall: stays put
        assert float(reward) == 10.0 and not bool(done)  # a pellet lies on both the start and its neighbours


def test_action_mask_matches_jumanji_along_an_episode(full_env, full_step):
    state, obs = full_env.reset(jax.random.PRNGKey(1))
    for t in range(12):
        np.testing.assert_array_equal(obs.action_mask, pacman.action_mask_of(state))
        state, obs, _, _ = full_step(state, random_legal_action(obs.action_mask, jax.random.PRNGKey(t)))


def test_score_is_the_sum_of_rewards_and_a_ghost_ends_the_episode(full_env, full_step):
    state, obs = full_env.reset(jax.random.PRNGKey(2))
    total = 0.0
    for t in range(full_env.spec.horizon):
        state, obs, reward, done = full_step(state, random_legal_action(obs.action_mask, jax.random.PRNGKey(t)))
        total += float(reward)
        if bool(done):
            break
    assert bool(done) and bool(state.game.dead) and t + 1 < full_env.spec.horizon  # a random player is caught
    assert total == float(state.game.score) > 0


def test_horizon_is_jumanjis_time_limit():
    env = envs.make("pacman-po", horizon=5)
    step = jax.jit(env.step)
    state, obs = env.reset(jax.random.PRNGKey(0))
    dones = []
    for action in (LEFT, LEFT, RIGHT, RIGHT, RIGHT):  # ghosts are still leaving their house: no capture yet
        state, obs, _, done = step(state, jnp.int32(action))
        dones.append(bool(done))
    assert dones == [False] * 4 + [True]
    assert float(obs.vector[-1]) == 1.0


def test_full_observation_layout(full_env, full_step, initial):
    _, obs = full_env.reset(jax.random.PRNGKey(0))
    vector = np.asarray(obs.vector)
    np.testing.assert_allclose(vector[:2], np.array(START) / [31, 28])
    ghosts = np.asarray(pacman.ghost_cells(initial.game))
    np.testing.assert_allclose(vector[2:10], (ghosts / [31, 28]).reshape(-1), rtol=1e-6)
    coarse = vector[19:75]
    assert coarse.max() == 1.0 and set(np.unique(coarse)) <= {0.0, 1.0}  # every pellet is still there
    state, obs, _, _ = full_step(initial, jnp.int32(LEFT))
    eaten_block = np.asarray(obs.vector[19:75]) < np.where(coarse > 0, 1.0, 0.0)
    assert eaten_block.sum() == 1  # the block of the eaten pellet, and only it, has fewer pellets
    # the full observation shows a ghost anywhere in the maze
    moved = full_step(placed(initial, ghosts=FAR_GHOSTS), jnp.int32(NO_OP))[1].vector
    assert not np.allclose(moved[2:10], full_step(initial, jnp.int32(NO_OP))[1].vector[2:10])


@pytest.mark.parametrize("size", [5, 7])
def test_window_at_the_border_shows_outside_as_wall(maze, initial, size):
    corner = (1, 1)
    planes = np.asarray(pacman.window_planes(maze, placed(initial, player=corner).game, size))
    walls = expected_walls(corner, size)
    np.testing.assert_array_equal(planes[WALL], walls)
    assert planes[WALL][0].all() and planes[WALL][:, 0].all()  # beyond the top and left edges
    np.testing.assert_array_equal(planes[PELLET], ~walls)  # at the start every free cell holds a pellet
    assert not planes[GHOST].any()


def test_window_at_the_tunnel_shows_its_far_end_as_wall(maze, initial):
    planes = np.asarray(pacman.window_planes(maze, placed(initial, player=(14, 0)).game, 5))
    np.testing.assert_array_equal(planes[WALL][2], [True, True, False, False, False])
    np.testing.assert_array_equal(planes[WALL], expected_walls((14, 0), 5))


def test_ghost_visible_inside_the_window_only(maze, initial):
    player = (5, 5)
    inside = placed(initial, player=player, ghosts=[(6, 7)] + FAR_GHOSTS[1:])  # offset (+1, +2)
    planes = np.asarray(pacman.window_planes(maze, inside.game, 5))
    assert planes[GHOST][3, 4] and planes[GHOST].sum() == 1
    just_outside = placed(initial, player=player, ghosts=[(5, 8)] + FAR_GHOSTS[1:])  # offset (0, +3)
    assert not np.asarray(pacman.window_planes(maze, just_outside.game, 5))[GHOST].any()
    # nothing in the vector gives away a ghost beyond the window
    far_away = placed(initial, player=player, ghosts=[(20, 20)] + FAR_GHOSTS[1:])
    vector = lambda state: np.asarray(pacman.partial_vector(maze, state.game, 64, 5))
    np.testing.assert_array_equal(vector(just_outside), vector(far_away))
    assert not np.array_equal(vector(inside), vector(far_away))


def test_power_pellet_plane(maze, initial):
    planes = np.asarray(pacman.window_planes(maze, placed(initial, player=(5, 6)).game, 5))
    power = np.zeros((5, 5), bool)
    power[0, 2] = True  # the power pellet at row 3, col 6, two rows up
    np.testing.assert_array_equal(planes[POWER], power)


def test_partial_observation_hides_what_lies_beyond_the_window(po_env, maze, initial):
    state, obs = po_env.reset(jax.random.PRNGKey(0))
    np.testing.assert_array_equal(obs.vector, pacman.partial_vector(maze, state.game, 64, 5))
    np.testing.assert_allclose(obs.vector[100:102], np.array(START) / [31, 28])
    # a pellet eaten far away changes nothing the player sees
    pellets = state.game.pellet_locations.at[0].set(0)  # Jumanji marks an eaten pellet as (0, 0)
    far = pacman.PacManState(state.game.replace(pellet_locations=pellets))
    np.testing.assert_array_equal(pacman.partial_vector(maze, far.game, 64, 5), obs.vector)


def test_random_reference_is_deterministic(po_env):
    initial_states, _ = jax.vmap(po_env.reset)(jax.random.split(jax.random.PRNGKey(0), 8))
    first = po_env.references(initial_states, np.zeros(8))
    assert set(first) == {"random_score"} and first["random_score"] > 0
    assert first == po_env.references(initial_states, np.zeros(8))


def test_render_both_variants(full_env, po_env, initial):
    outline = np.array([60, 255, 90])
    state = jax.tree_util.tree_map(np.asarray, initial)
    full, partial = full_env.render(state), po_env.render(state)
    for image in (full, partial):
        assert image.dtype == np.uint8 and image.ndim == 3 and image.shape == (31 * 12 + 22, 28 * 12, 3)
    assert not (full == outline).all(-1).any() and (partial == outline).all(-1).sum() > 100


@pytest.mark.parametrize(
    "name, args, message",
    [
        ("pacman", {"horizon": 0}, "pacman: horizon must be an integer at least 1, got 0"),
        ("pacman", {"horizon": -1}, "pacman: horizon must be an integer at least 1, got -1"),
        ("pacman-po", {"horizon": 1.5}, "pacman-po: horizon must be an integer at least 1, got 1.5"),
        ("pacman-po", {"window_size": 4}, "pacman-po: window_size must be an odd integer at least 1, got 4"),
        ("pacman-po", {"window_size": 0}, "pacman-po: window_size must be an odd integer at least 1, got 0"),
        ("pacman-po", {"window_size": -3}, "pacman-po: window_size must be an odd integer at least 1, got -3"),
        ("pacman-po", {"window_size": "5"}, "pacman-po: window_size must be an odd integer at least 1, got '5'"),
        ("pacman", {"window_size": 5}, "pacman: window_size must be left out (it applies to pacman-po only), got 5"),
        ("pacman-po", {"partial": False}, "bad parameters"),
    ],
)
def test_bad_parameters_are_one_line_errors(name, args, message):
    with pytest.raises(ValueError) as error:
        envs.make(name, **args)
    assert message in str(error.value) and "\n" not in str(error.value)


def test_partial_must_be_a_bool():
    with pytest.raises(ValueError, match="^pacman: partial must be true or false, got 'yes'$"):
        pacman.make(partial="yes")


def test_reseed_changes_only_the_key_the_ghosts_draw_from(full_env, po_env, initial):
    assert po_env.reseed is not None
    reseeded = full_env.reseed(initial, jax.random.PRNGKey(7))
    assert not np.array_equal(reseeded.game.key, initial.game.key)
    same = jax.tree_util.tree_map(lambda a, b: bool(np.array_equal(a, b)),
                                  reseeded.game.replace(key=initial.game.key), initial.game)
    assert all(jax.tree_util.tree_leaves(same))
