import itertools

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from pizero_ray import envs
from pizero_ray.envs import tsp


def _distance_matrix(coords):
    return np.sqrt(((coords[:, None] - coords[None]) ** 2).sum(-1))


def _brute_force(coords):
    d = _distance_matrix(coords)
    n = len(coords)
    best = np.inf
    for perm in itertools.permutations(range(1, n)):
        tour = (0,) + perm
        best = min(best, sum(d[tour[i], tour[(i + 1) % n]] for i in range(n)))
    return best


def test_reset_shapes_and_spec(tsp_env):
    state, obs = tsp_env.reset(jax.random.PRNGKey(0))
    spec = tsp_env.spec
    assert spec.num_actions == 10 and spec.horizon == 10 and spec.discrete
    assert obs.vector.shape == (spec.observation_size,)
    assert obs.action_features.shape == (10, spec.action_feature_size)
    assert obs.action_mask.shape == (10,) and bool(obs.action_mask.all())
    assert np.all((np.asarray(state.coordinates) >= 0) & (np.asarray(state.coordinates) <= 1))


def test_swap_places_the_chosen_city_and_masks_it(tsp_env):
    state, _ = tsp_env.reset(jax.random.PRNGKey(1))
    state, obs, reward, done = tsp_env.step(state, jnp.int32(7))
    assert list(np.asarray(state.tour)) == [7, 1, 2, 3, 4, 5, 6, 0, 8, 9]
    assert not bool(obs.action_mask[7]) and int(obs.action_mask.sum()) == 9
    assert float(reward) == 0.0 and not bool(done)
    state, obs, _, _ = tsp_env.step(state, jnp.int32(0))
    assert list(np.asarray(state.tour)[:2]) == [7, 0]
    # city 0 is now the previous city: its features say so
    np.testing.assert_allclose(obs.action_features[3, 2:4], state.coordinates[0])


def test_score_is_minus_the_closed_tour_after_n_steps(tsp_env):
    state, _ = tsp_env.reset(jax.random.PRNGKey(2))
    order = [3, 1, 4, 0, 5, 9, 2, 6, 8, 7]
    rewards, dones = [], []
    for city in order:
        state, _, reward, done = tsp_env.step(state, jnp.int32(city))
        rewards.append(float(reward))
        dones.append(bool(done))
    assert dones == [False] * 9 + [True]
    assert list(np.asarray(state.tour)) == order
    coords = np.asarray(state.coordinates)[order]
    expected = np.linalg.norm(coords - np.roll(coords, -1, axis=0), axis=1).sum()
    assert rewards[:-1] == [0.0] * 9
    assert rewards[-1] == pytest.approx(-expected, rel=1e-5)


def test_unmasked_variant_allows_disturbing_placed_positions():
    env = envs.make("tsp", num_cities=5, mask_placed=False)
    state, _ = env.reset(jax.random.PRNGKey(0))
    state, _, _, _ = env.step(state, jnp.int32(3))
    state, obs, _, _ = env.step(state, jnp.int32(3))  # swap city 3 from position 0 into position 1
    assert bool(obs.action_mask.all())
    assert list(np.asarray(state.tour)) == [1, 3, 2, 0, 4]


def test_held_karp_matches_brute_force():
    coords = np.random.default_rng(0).uniform(size=(3, 7, 2))
    exact = tsp.optimal_tour_length(coords)
    for c, value in zip(coords, exact):
        assert value == pytest.approx(_brute_force(c))


def test_reference_solvers_on_a_square():
    square = np.array([[0, 0], [1, 1], [1, 0], [0, 1]], dtype=float)
    assert tsp.optimal_tour_length(square) == pytest.approx(4.0)
    assert tsp.nearest_neighbour_tour_length(square) == pytest.approx(4.0)


def test_reference_scale_of_uniform_tsp10():
    coords = np.random.default_rng(1).uniform(size=(300, 10, 2))
    optimal = tsp.optimal_tour_length(coords).mean()
    nearest = tsp.nearest_neighbour_tour_length(coords).mean()
    assert 2.75 < optimal < 2.97  # ~2.86 for uniform TSP10
    assert 3.05 < nearest < 3.3  # ~3.17
    assert nearest > optimal


@pytest.mark.parametrize(
    "args, message",
    [
        ({"num_cities": 1}, "tsp: num_cities must be an integer at least 3, got 1"),
        ({"num_cities": 10.0}, "tsp: num_cities must be an integer at least 3, got 10.0"),
        ({"num_cities": True}, "tsp: num_cities must be an integer at least 3, got True"),
        ({"mask_placed": "false"}, "tsp: mask_placed must be true or false, got 'false'"),
        ({"mask_placed": 1}, "tsp: mask_placed must be true or false, got 1"),
        ({"features": "nearest"}, "tsp: features must be one of distances, paper, got 'nearest'"),
    ],
)
def test_bad_parameter_values_are_one_line_errors(args, message):
    with pytest.raises(ValueError) as error:
        envs.make("tsp", **args)
    assert str(error.value) == message


def test_bad_parameters_are_one_line_errors():
    with pytest.raises(ValueError, match="unknown environment 'chess'"):
        envs.make("chess")
    with pytest.raises(ValueError, match="bad parameters"):
        envs.make("tsp", cities=10)
    with pytest.raises(ValueError, match="Held-Karp"):
        tsp.optimal_tour_length(np.zeros((13, 2)))


def test_paper_features_are_each_citys_coordinates_and_placed_flag_only(tsp_env):
    env = envs.make("tsp", features="paper")
    assert env.spec._replace(action_feature_size=0) == tsp_env.spec._replace(action_feature_size=0)
    assert env.spec.action_feature_size == 3
    key = jax.random.PRNGKey(4)
    state, obs = env.reset(key)
    rich_state, rich = tsp_env.reset(key)
    np.testing.assert_array_equal(np.asarray(obs.vector), np.asarray(rich.vector))  # flat coordinates + timestep
    np.testing.assert_array_equal(np.asarray(obs.action_features[:, :2]), np.asarray(state.coordinates))
    assert not np.asarray(obs.action_features[:, 2]).any()
    for city in (6, 2):
        state, obs, reward, done = env.step(state, jnp.int32(city))
        rich_state, rich, rich_reward, _ = tsp_env.step(rich_state, jnp.int32(city))
        assert float(reward) == float(rich_reward)  # the same game
    placed = np.asarray(obs.action_features[:, 2])
    assert list(np.flatnonzero(placed)) == [2, 6] and list(np.flatnonzero(~np.asarray(obs.action_mask))) == [2, 6]
    np.testing.assert_array_equal(np.asarray(obs.action_features[:, 2]), np.asarray(rich.action_features[:, 9]))


def _drawn_cities(t):
    """Cities at the corners of a square, tour 2, 0, 3, 1 placed up to position ``t``."""
    coordinates = np.array([[0.8, 0.2], [0.8, 0.8], [0.2, 0.2], [0.2, 0.8]], np.float32)
    return tsp.TSPState(coordinates, np.array([2, 0, 3, 1], np.int32), np.int32(t))


def _pixel(image, x, y):
    size = image.shape[0]
    margin = size // 20
    return tuple(image[round(size - margin - y * (size - 2 * margin)), round(margin + x * (size - 2 * margin))])


def test_render_fills_the_first_city_and_draws_the_tour_as_lines():
    white = (255, 255, 255)
    image = tsp.render(_drawn_cities(3), size=200)
    assert image.shape == (200, 200, 3) and image.dtype == np.uint8
    assert _pixel(image, 0.2, 0.2) == tsp.CITY_COLOUR  # city 2, the first: filled
    assert _pixel(image, 0.8, 0.2) == _pixel(image, 0.2, 0.8) == _pixel(image, 0.8, 0.8) == white  # others hollow
    assert _pixel(image, 0.5, 0.2) == _pixel(image, 0.35, 0.65) == tsp.TOUR_COLOUR  # 2 -> 0 -> 3
    assert _pixel(image, 0.5, 0.8) == _pixel(image, 0.35, 0.35) == white  # 3 -> 1 -> 2: not yet
    closed = tsp.render(_drawn_cities(4), size=200)
    assert _pixel(closed, 0.5, 0.8) == _pixel(closed, 0.35, 0.35) == tsp.TOUR_COLOUR
    assert _pixel(tsp.render(_drawn_cities(0), size=200), 0.2, 0.2) == white  # no first city before one is placed


def test_placed_path_length_is_open_until_the_tour_closes():
    side, diagonal = 0.6, np.hypot(0.6, 0.6)
    assert tsp.placed_path_length(_drawn_cities(0)) == 0.0
    assert tsp.placed_path_length(_drawn_cities(3)) == pytest.approx(side + diagonal)
    assert tsp.placed_path_length(_drawn_cities(4)) == pytest.approx(2 * side + 2 * diagonal)
    assert tsp.placed_path_length(_drawn_cities(4)) == pytest.approx(float(tsp.tour_length(*_drawn_cities(4)[:2])))
