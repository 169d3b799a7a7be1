"""Sokoban rules, observation, batching, references and rendering, from hand-built levels."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from pizero_ray import envs
from pizero_ray.envs import boxoban, sokoban

UP, DOWN, LEFT, RIGHT = range(4)

# Hand-built levels (10x10, text format). The player starts at '@'.
PUSHES = """\
##########
#        #
#  $ #   #
#  @$$ . #
#   $    #
#   .    #
#   .    #
#        #
#.       #
##########"""

ONE_BOX_NEXT_TO_GOAL = """\
##########
#        #
#        #
#  @$.   #
#        #
#        #
#        #
#        #
#        #
##########"""

STARTS_COVERED = """\
##########
#        #
#  @ $.  #
#   *    #
#        #
#        #
#        #
#        #
#        #
##########"""

# No walls at all: the grid's edge must act as one.
NO_BORDER = "\n".join(["  @$      ", *[" " * 10] * 7, "        . ", " " * 10])


def _codes(level: str) -> np.ndarray:
    return boxoban.parse_levels("; 0\n" + level + "\n")[0]


def _state(level: str) -> sokoban.SokobanState:
    return sokoban.state_from_codes(_codes(level))


@pytest.fixture(scope="module")
def env():
    return envs.make("sokoban", num_levels=50)


@pytest.fixture(scope="module")
def step(env):
    return jax.jit(env.step)


def _play(step, state, actions):
    rewards, dones = [], []
    for action in actions:
        state, _, reward, done = step(state, jnp.int32(action))
        rewards.append(float(reward))
        dones.append(bool(done))
    return state, rewards, dones


def _boxes(state):
    return sorted(map(tuple, np.argwhere(np.asarray(state.boxes)).tolist()))


def _player(state):
    return tuple(np.asarray(state.player).tolist())


def test_spec_and_observation(env, step):
    spec = env.spec
    assert spec.discrete and spec.num_actions == 4 and spec.horizon == 50
    assert spec.observation_size == 4 * 100 + 1 and spec.action_feature_size == 4
    state, obs = jax.jit(env.reset)(jax.random.PRNGKey(0))
    assert obs.vector.shape == (spec.observation_size,)
    np.testing.assert_array_equal(obs.action_features, np.eye(4))
    assert obs.action_mask.shape == (4,) and bool(obs.action_mask.all())
    planes = np.asarray(obs.vector[:-1]).reshape(4, 10, 10)
    np.testing.assert_array_equal(planes[0], state.walls)
    np.testing.assert_array_equal(planes[1], state.goals)
    np.testing.assert_array_equal(planes[2], state.boxes)
    assert planes[3].sum() == 1 and planes[3][tuple(np.asarray(state.player))] == 1
    assert float(obs.vector[-1]) == 0.0
    _, obs, _, _ = step(state, jnp.int32(UP))
    assert float(obs.vector[-1]) == pytest.approx(1 / 50)


def test_walk_and_push_into_free_floor(step):
    state = _state(PUSHES)
    assert _player(state) == (3, 3)
    state, _, _ = _play(step, state, [DOWN])  # walk
    assert _player(state) == (4, 3)
    state, _, _ = _play(step, state, [RIGHT])  # push the box at (4, 4) to (4, 5)
    assert _player(state) == (4, 4) and (4, 5) in _boxes(state) and (4, 4) not in _boxes(state)


def test_pushes_against_walls_and_boxes_leave_everything_in_place(step):
    start = _state(PUSHES)
    # right: the box at (3, 4) is pushed against the box at (3, 5)
    state, rewards, _ = _play(step, start, [RIGHT])
    assert _player(state) == (3, 3) and _boxes(state) == _boxes(start) and rewards == [0.0]
    # the box at (2, 3) pushed up reaches (1, 3), then a second push meets the border wall
    state, _, _ = _play(step, start, [UP])
    assert _player(state) == (2, 3) and (1, 3) in _boxes(state)
    after_wall, _, _ = _play(step, state, [UP])
    assert _player(after_wall) == (2, 3) and _boxes(after_wall) == _boxes(state)
    # walking into a wall
    state, _, _ = _play(step, start, [LEFT, LEFT])
    assert _player(state) == (3, 1)
    state, _, _ = _play(step, state, [LEFT])
    assert _player(state) == (3, 1) and _boxes(state) == _boxes(start)


def test_push_into_a_wall_beside_the_box(step):
    level = """\
##########
#        #
#  @$#   #
#        #
#        #
#        #
#        #
#.       #
##########
##########"""
    start = _state(level)
    state, _, _ = _play(step, start, [RIGHT])
    assert _player(state) == (2, 3) and _boxes(state) == _boxes(start)


def test_no_pulls(step):
    start = _state(ONE_BOX_NEXT_TO_GOAL)
    state, rewards, _ = _play(step, start, [LEFT, LEFT])
    assert _player(state) == (3, 1) and _boxes(state) == [(3, 4)] and rewards == [0.0, 0.0]


def test_push_onto_a_goal_solves_and_ends_early(step):
    state, rewards, dones = _play(step, _state(ONE_BOX_NEXT_TO_GOAL), [RIGHT])
    assert _boxes(state) == [(3, 5)] and rewards == [1.0] and dones == [True]
    assert bool(sokoban.is_solved(state)) and int(sokoban.covered_goals(state)) == 1


def test_rewards_sum_to_goals_covered_at_the_end(step):
    start = _state(STARTS_COVERED)  # one of two boxes starts on its goal
    assert int(sokoban.covered_goals(start)) == 1
    # the first step pays the goal covered at reset; pushing that box off (right) and, from
    # the other side, back on (left) nets zero
    state, rewards, dones = _play(step, start, [DOWN, RIGHT])
    assert rewards == [1.0, -1.0] and sum(rewards) == int(sokoban.covered_goals(state)) == 0
    state, more, dones = _play(step, state, [DOWN, RIGHT, RIGHT, UP, LEFT])
    rewards += more
    assert more == [0.0] * 4 + [1.0] and sum(rewards) == int(sokoban.covered_goals(state)) == 1
    assert not any(dones)
    # finish: walk round to (2, 4) and push the other box onto its goal
    state, more, dones = _play(step, state, [DOWN, LEFT, LEFT, UP, UP, RIGHT, RIGHT])
    rewards += more
    assert more[-1] == 1.0 and dones == [False] * 6 + [True]
    assert sum(rewards) == int(sokoban.covered_goals(state)) == 2 and bool(sokoban.is_solved(state))


def test_first_step_pays_what_reset_covered(step):
    state, rewards, _ = _play(step, _state(STARTS_COVERED), [UP])
    assert rewards == [1.0]


def test_off_the_grid_is_a_wall(step):
    start = _state(NO_BORDER)
    state, _, _ = _play(step, start, [UP])
    assert _player(state) == (0, 2)
    # the box at (0, 3) cannot go up off the grid: walk under it, push up
    state, _, _ = _play(step, start, [DOWN, RIGHT, UP])
    assert _player(state) == (1, 3) and _boxes(state) == [(0, 3)]
    # pushing the box along the top row to the right edge, then once more: it stays
    state, _, _ = _play(step, start, [RIGHT] * 7)
    assert _boxes(state) == [(0, 9)] and _player(state) == (0, 8)
    state, _, _ = _play(step, state, [RIGHT])
    assert _boxes(state) == [(0, 9)] and _player(state) == (0, 8)


def test_done_at_the_horizon():
    env = envs.make("sokoban", horizon=3, num_levels=5)
    state = _state(ONE_BOX_NEXT_TO_GOAL)
    _, _, dones = _play(jax.jit(env.step), state, [LEFT, UP, DOWN])
    assert dones == [False, False, True]


def test_reset_samples_every_level_of_a_bank(tmp_path):
    levels = [ONE_BOX_NEXT_TO_GOAL, STARTS_COVERED, PUSHES]
    path = tmp_path / "three.txt"
    path.write_text("".join(f"; {i}\n{level}\n\n" for i, level in enumerate(levels)))
    env = envs.make("sokoban", levels=str(path))
    states, _ = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.PRNGKey(0), 64))
    assert set(np.asarray(states.level).tolist()) == {0, 1, 2}
    for e in range(4):
        expected = _state(levels[int(states.level[e])])
        for field in ("walls", "goals", "boxes", "player"):
            np.testing.assert_array_equal(getattr(states, field)[e], getattr(expected, field))


def test_references_report_solved_fractions_and_a_fixed_random_agent(env):
    states, _ = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.PRNGKey(1), 32))
    scores = np.array([4.0] * 8 + [1.0] * 24)
    first = env.references(states, scores)
    assert first["solved_fraction"] == pytest.approx(0.25) and first["mean_boxes"] == 4.0
    assert 0.0 <= first["random_goals_covered"] <= 4.0
    assert 0.0 <= first["random_solved_fraction"] <= 1.0
    assert env.references(states, scores) == first  # the random agent's key is fixed


def test_random_agent_sometimes_solves_a_one_push_level(env):
    states = jax.tree_util.tree_map(lambda x: jnp.stack([x] * 64), _state(ONE_BOX_NEXT_TO_GOAL))
    random_agent = jax.jit(lambda states, key: sokoban.random_agent_scores(env.step, states, 50, key))
    scores = np.asarray(random_agent(states, jax.random.PRNGKey(0)))
    assert set(scores.tolist()) <= {0.0, 1.0} and 0.0 < scores.mean() < 1.0


def test_render_draws_boxes_on_goals_in_their_own_colour(env, step):
    start = _state(ONE_BOX_NEXT_TO_GOAL)
    before = env.render(start)
    after = env.render(step(start, jnp.int32(RIGHT))[0])
    assert before.dtype == np.uint8 and before.shape == (10 * 32 + 22, 10 * 32, 3)

    def tile(image, row, col):  # the centre of a box is its fill colour
        return tuple(image[22 + row * 32 + 10, col * 32 + 16])

    assert tile(before, 3, 4) == sokoban.COLOURS["box"]
    assert tile(after, 3, 5) == sokoban.COLOURS["box_on_goal"]


def test_spec_does_not_depend_on_the_levels(env, tmp_path):
    path = tmp_path / "one.txt"
    path.write_text(f"; 0\n{PUSHES}\n")
    assert envs.make("sokoban", levels=str(path)).spec == env.spec


def test_centred_view_shows_walls_goals_and_boxes_around_the_player():
    env = envs.make("sokoban", num_levels=5, view="centred", view_radius=2)
    assert env.spec.observation_size == 3 * 25 + 1
    state = _state(ONE_BOX_NEXT_TO_GOAL)  # player (3, 3), box (3, 4), goal (3, 5)
    _, obs, _, _ = env.step(state, jnp.int32(UP))  # the player moves to (2, 3)
    walls, goals, boxes = np.asarray(obs.vector[:-1]).reshape(3, 5, 5)
    assert walls[0].all() and walls.sum() == 5  # the top wall (row 0) is two rows up, nothing else
    assert boxes.sum() == 1 and boxes[3, 3] == 1  # one down, one right
    assert goals.sum() == 1 and goals[3, 4] == 1  # one down, two right
    assert float(obs.vector[-1]) == pytest.approx(1 / 50)


def test_centred_view_reads_off_the_grid_as_wall():
    env = envs.make("sokoban", num_levels=5, view="centred", view_radius=1)
    state = _state(NO_BORDER)  # player (0, 2), box (0, 3), no walls
    walls, _, boxes = np.asarray(env.step(state, jnp.int32(LEFT))[1].vector[:-1]).reshape(3, 3, 3)
    np.testing.assert_array_equal(walls, [[1, 1, 1], [0, 0, 0], [0, 0, 0]])  # the player is now at (0, 1)
    assert boxes.sum() == 0  # the box at (0, 3) is two to the right: outside a radius of 1


@pytest.mark.parametrize(
    "args, message",
    [
        ({"horizon": 0}, "sokoban: horizon must be an integer at least 1, got 0"),
        ({"horizon": True}, "horizon must be an integer at least 1, got True"),
        ({"num_levels": 0}, "num_levels must be an integer at least 1, got 0"),
        ({"num_boxes": 9}, "num_boxes must be an integer in 1..8, got 9"),
        ({"generator_seed": -1}, "generator_seed must be an integer at least 0, got -1"),
        ({"pull_rounds": "many"}, "pull_rounds must be an integer at least 1, got 'many'"),
        ({"levels": "/nowhere/boxoban"}, "sokoban: levels path /nowhere/boxoban does not exist"),
        ({"levels": 3}, "levels must be a file or directory path, got 3"),
        ({"levels": ""}, "sokoban: levels must be a file or directory path, got ''"),
        ({"horizon": 50.0}, "sokoban: horizon must be an integer at least 1, got 50.0"),
        ({"size": 3}, "bad parameters for environment 'sokoban'"),
        ({"view": "local"}, "sokoban: view must be one of absolute, centred, got 'local'"),
        ({"view": "centred", "view_radius": 10}, "sokoban: view_radius must be an integer in 1..9, got 10"),
    ],
)
def test_bad_parameters_are_one_line_errors(args, message):
    with pytest.raises(ValueError) as error:
        envs.make("sokoban", **args)
    assert message in str(error.value) and "\n" not in str(error.value)


def test_empty_level_directory_is_an_error(tmp_path):
    with pytest.raises(ValueError) as error:
        envs.make("sokoban", levels=str(tmp_path))
    assert str(error.value) == f"sokoban: no level files (*.txt) in {tmp_path}"


def test_training_presets_build_valid_configs():
    from pizero_ray.config import build_config
    from pizero_ray.presets import ENV_PRESETS

    assert set(ENV_PRESETS["sokoban"]) >= {"default", "paper"}
    for preset in ("default", "paper", "tiny"):
        config = build_config(preset, env="sokoban")
        assert config.env == "sokoban"
    assert build_config("default", env="sokoban").population == ENV_PRESETS["sokoban"]["default"]["population"]
