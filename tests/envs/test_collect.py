import itertools
import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from pizero_ray import envs
from pizero_ray.envs import collect
from pizero_ray.envs.collect import DOWN, LEFT, RIGHT, UP, CollectState


@pytest.fixture(scope="module")
def env():
    return envs.make("collect")


def _state(agent, coins, t=0, size=8):
    grid = np.zeros((size, size), dtype=bool)
    for cell in coins:
        grid[cell] = True
    return CollectState(jnp.asarray(agent, jnp.int32), jnp.asarray(grid), jnp.int32(t))


def _walk(env, state, actions):
    rewards, dones = [], []
    for action in actions:
        state, obs, reward, done = env.step(state, jnp.int32(action))
        rewards.append(float(reward))
        dones.append(bool(done))
    return state, obs, rewards, dones


def test_reset_shapes_and_spec(env):
    state, obs = env.reset(jax.random.PRNGKey(0))
    spec = env.spec
    assert spec.discrete and spec.num_actions == 4 and spec.horizon == 20
    assert spec.observation_size == 2 * 36 + 20 == obs.vector.shape[0]
    np.testing.assert_array_equal(obs.action_features, np.eye(4))
    assert obs.action_mask.shape == (4,) and bool(obs.action_mask.all())
    vector = np.asarray(obs.vector)
    assert vector[:36].sum() == 12 and vector[36:72].sum() == 1 and vector[72] == 1.0  # coins, agent, t = 0
    assert int(state.t) == 0


def test_reset_places_agent_and_coins_on_distinct_interior_cells(env):
    states, _ = jax.vmap(env.reset)(jax.random.split(jax.random.PRNGKey(1), 300))
    coins, agent = np.asarray(states.coins), np.asarray(states.agent)
    walls = collect.border_walls(8)
    assert (coins.sum(axis=(1, 2)) == 12).all()
    assert not (coins & walls).any()
    assert ((agent >= 1) & (agent <= 6)).all()
    assert not coins[np.arange(300), agent[:, 0], agent[:, 1]].any()
    # uniform placement: every interior cell gets coins, none much more than its share
    per_cell = coins.sum(axis=0)[1:-1, 1:-1]
    assert per_cell.min() > 0 and per_cell.max() < 3 * 300 * 12 / 36


def test_moving_into_a_wall_leaves_the_agent_in_place(env):
    state = _state((1, 1), [(6, 6)])
    for action in (UP, LEFT):
        moved, _, reward, _ = env.step(state, jnp.int32(action))
        assert list(np.asarray(moved.agent)) == [1, 1] and float(reward) == 0.0
    corner = _state((6, 6), [(1, 1)])
    for action in (DOWN, RIGHT):
        assert list(np.asarray(env.step(corner, jnp.int32(action))[0].agent)) == [6, 6]
    moved = env.step(state, jnp.int32(RIGHT))[0]
    assert list(np.asarray(moved.agent)) == [1, 2]
    assert list(np.asarray(env.step(state, jnp.int32(DOWN))[0].agent)) == [2, 1]


def test_a_coin_is_collected_once_when_entered(env):
    state = _state((2, 1), [(2, 2), (2, 3), (5, 5)])
    left = []
    for action in [RIGHT, RIGHT, LEFT, RIGHT, UP]:
        state, obs, reward, _ = env.step(state, jnp.int32(action))
        left.append(int(np.asarray(state.coins).sum()))
        assert float(reward) == 0.0  # the score comes at the end
    assert left == [2, 1, 1, 1, 1]
    assert bool(state.coins[5, 5]) and list(np.asarray(state.agent)) == [1, 3]
    assert np.asarray(obs.vector)[:36].sum() == 1  # the observation's coin plane agrees
    assert np.asarray(obs.vector)[36 + 2].item() == 1.0  # agent plane: interior cell (0, 2)


def test_score_is_minus_the_coins_left_after_the_horizon(env):
    state = _state((1, 1), [(1, 2), (1, 3), (4, 4), (6, 1)])
    actions = [RIGHT, RIGHT] + [UP] * 18  # two coins, then bumps into the top wall
    state, obs, rewards, dones = _walk(env, state, actions)
    assert dones == [False] * 19 + [True]
    assert rewards == [0.0] * 19 + [-2.0]
    assert np.asarray(state.coins).sum() == 2
    assert np.asarray(obs.vector)[72:].sum() == 0  # no timestep left


def test_greedy_goes_to_the_nearest_coin_vertically_first():
    # (3, 5) and (5, 3) are both 2 away from (3, 3): the lower row-major index, (3, 5), wins
    state = _state((3, 3), [(3, 5), (5, 3), (6, 6)])
    assert int(collect.greedy_action(state)) == RIGHT
    state = _state((3, 3), [(1, 4), (6, 6)])
    assert int(collect.greedy_action(state)) == UP
    state = _state((3, 3), [(5, 1)])
    assert int(collect.greedy_action(state)) == DOWN
    state = _state((3, 3), [(3, 1), (6, 6)])
    assert int(collect.greedy_action(state)) == LEFT


def test_exact_optimum_matches_brute_force_over_all_walks():
    env = collect.make(num_coins=5, horizon=6)
    states, _ = jax.vmap(env.reset)(jax.random.split(jax.random.PRNGKey(3), 12))
    walks = jnp.asarray(list(itertools.product(range(4), repeat=6)), jnp.int32)  # all 4^6 walks

    def coins_left(state, walk):
        final = jax.lax.fori_loop(0, 6, lambda t, s: env.step(s, walk[t])[0], state)
        return final.coins.sum()

    every_walk = jax.jit(jax.vmap(jax.vmap(coins_left, in_axes=(None, 0)), in_axes=(0, None)))
    best = 5 - np.asarray(every_walk(states, walks)).min(axis=1)
    exact = collect.optimal_coins_collected(states.agent, states.coins, horizon=6)
    np.testing.assert_array_equal(exact, best)
    assert best.min() < best.max()  # the instances are not all alike


def test_references_are_in_sensible_order(env):
    states, _ = jax.vmap(env.reset)(jax.random.split(jax.random.PRNGKey(4), 200))
    optimal = collect.optimal_coins_collected(states.agent, states.coins, 20) - 12
    greedy, random = collect.walker_scores(env.step, 20, states)
    assert (np.asarray(greedy) <= optimal).all() and (np.asarray(random) <= optimal).all()
    out = env.references(states, optimal - 1.0)
    assert set(out) == {"greedy_score", "random_score", "optimal_score", "mean_gap_to_optimal"}
    assert out["greedy_score"] == pytest.approx(float(np.mean(greedy)))
    assert out["random_score"] < out["greedy_score"] < out["optimal_score"]
    assert out["mean_gap_to_optimal"] == pytest.approx(1.0)
    assert -1.5 < out["greedy_score"] < -0.6 and -0.7 < out["optimal_score"] < -0.2  # ~-1.0 and ~-0.4


def test_no_exact_optimum_for_many_coins():
    with pytest.raises(ValueError, match="at most 12"):
        collect.optimal_coins_collected(np.ones((1, 2)), np.ones((1, 4, 4)), 20)


def test_render_draws_walls_coins_and_agent(env):
    state = _state((2, 3), [(5, 4)], t=7)
    image = env.render(state)
    cell, header = collect.CELL, collect.HEADER.height
    assert image.shape == (8 * cell + header, 8 * cell, 3) and image.dtype == np.uint8
    centre = lambda r, c: tuple(image[header + r * cell + cell // 2, c * cell + cell // 2])
    assert centre(0, 0) == collect.WALL_COLOUR
    assert centre(5, 4) == collect.COIN_COLOUR
    assert centre(2, 3) == collect.AGENT_COLOUR
    assert centre(4, 4) == collect.FLOOR_COLOUR


def test_centred_view_shows_the_agent_in_the_middle_of_coins_and_walls():
    env = envs.make("collect", view="centred")
    assert env.spec.observation_size == 2 * 11 * 11 + 20
    state = _state((1, 2), [(1, 3), (6, 6)], t=3)
    vector = np.asarray(env.step(state, jnp.int32(DOWN))[1].vector)  # the agent moves to (2, 2) at t = 4
    assert vector.shape == (262,)
    coins, walls, timestep = vector[:121].reshape(11, 11), vector[121:242].reshape(11, 11), vector[242:]
    assert timestep.argmax() == 4 and timestep.sum() == 1
    # offsets from the middle cell (5, 5): the coin at (1, 3) is one up and one right, (6, 6) four down, four right
    assert coins.sum() == 2 and coins[4, 6] == 1 and coins[9, 9] == 1
    # the border row 0 is two up; everything above it is off the grid, so wall too
    assert walls[:4].all() and not walls[4:10, 4:10].any() and walls[:, :4].all() and walls[10].all()


def test_centred_view_is_the_same_input_wherever_the_agent_stands():
    env = envs.make("collect", view="centred")
    here = env.step(_state((2, 2), [(2, 3)]), jnp.int32(UP))[1].vector  # agent (1, 2), coin one down, one right
    there = env.step(_state((4, 4), [(4, 5)]), jnp.int32(UP))[1].vector  # agent (3, 4), coin one down, one right
    coins = lambda v: np.asarray(v[:121]).reshape(11, 11)
    np.testing.assert_array_equal(coins(here), coins(there))
    assert coins(here)[6, 6] == 1 and coins(here).sum() == 1


@pytest.mark.parametrize(
    "args, named",
    [
        ({"num_coins": 0}, "num_coins must be an integer in 1..35, got 0"),
        ({"num_coins": 36}, "got 36"),
        ({"horizon": 0}, "horizon must be an integer at least 1, got 0"),
        ({"size": 3}, "size must be an integer at least 4, got 3"),
        ({"num_coins": 2.5}, "got 2.5"),
        ({"horizon": True}, "collect: horizon must be an integer at least 1, got True"),
        ({"size": "8"}, "collect: size must be an integer at least 4, got '8'"),
        ({"coins": 3}, "bad parameters for environment 'collect'"),
        ({"view": "egocentric"}, "collect: view must be one of absolute, centred, got 'egocentric'"),
    ],
)
def test_bad_parameters_are_one_line_errors(args, named):
    with pytest.raises(ValueError, match=named) as error:
        envs.make("collect", **args)
    assert "\n" not in str(error.value)


def test_eval_and_render_from_the_cli(tmp_path, capsys):
    """A run dir without checkpoints holds the untrained agent: enough for the CLI's env paths, no Ray."""
    from pizero_ray.cli import main
    from pizero_ray.config import build_config
    from pizero_ray.storage import run_dir

    path = tmp_path / "run"
    run_dir.write_config(path, build_config("tiny", env="collect", planner="none"))  # the cheapest agent to compile
    assert main(["eval", str(path), "--episodes", "16", "--json"]) == 0
    evaluation = json.loads(capsys.readouterr().out)
    assert evaluation["env"] == "collect" and -12 <= evaluation["mean_score"] <= 0
    assert evaluation["random_score"] < evaluation["greedy_score"] <= evaluation["optimal_score"]
    gif = tmp_path / "episode.gif"
    assert main(["render", str(path), "--out", str(gif)]) == 0
    from PIL import Image

    with Image.open(gif) as image:
        assert image.n_frames == 21  # the initial state and one frame per step
