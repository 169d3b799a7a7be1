import itertools
import json

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from pizero_ray import envs
from pizero_ray.envs import flp
from pizero_ray.envs.flp import FLPState

SQUARE = [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)]


@pytest.fixture(scope="module")
def env():
    return envs.make("flp")


def _state(clients, num_facilities):
    clients = jnp.asarray(clients, jnp.float32)
    return FLPState(clients, jnp.zeros((num_facilities, 2), jnp.float32), jnp.int32(0))


def _place(env, state, points):
    rewards, dones = [], []
    for point in points:
        state, obs, reward, done = env.step(state, jnp.asarray(point, jnp.float32))
        rewards.append(float(reward))
        dones.append(bool(done))
    return state, obs, rewards, dones


def _enclosing_radius(points):
    """Smallest enclosing circle by brute force: diametral circles of pairs, circumcircles of triples."""
    points = np.asarray(points, dtype=np.float64)
    if len(points) == 1:
        return 0.0
    candidates = [((a + b) / 2, np.linalg.norm(a - b) / 2) for a, b in itertools.combinations(points, 2)]
    for a, b, c in itertools.combinations(points, 3):
        d = 2 * (a[0] * (b[1] - c[1]) + b[0] * (c[1] - a[1]) + c[0] * (a[1] - b[1]))
        if abs(d) < 1e-12:
            continue
        sq = [p @ p for p in (a, b, c)]
        centre = np.array([sq[0] * (b[1] - c[1]) + sq[1] * (c[1] - a[1]) + sq[2] * (a[1] - b[1]),
                           sq[0] * (c[0] - b[0]) + sq[1] * (a[0] - c[0]) + sq[2] * (b[0] - a[0])]) / d
        candidates.append((centre, np.linalg.norm(a - centre)))
    return min(r for centre, r in candidates if np.linalg.norm(points - centre, axis=1).max() <= r + 1e-9)


def _optimal_radius(clients, num_facilities):
    """Exact continuous k-center: the best split of the clients into groups, each covered by its enclosing circle."""
    best = np.inf
    for labels in itertools.product(range(num_facilities), repeat=len(clients)):
        labels = np.array(labels)
        groups = [clients[labels == g] for g in range(num_facilities) if (labels == g).any()]
        best = min(best, max(_enclosing_radius(group) for group in groups))
    return best


def test_spec_and_observation_of_a_continuous_env(env):
    spec = env.spec
    assert not spec.discrete and spec.num_actions == 0 and spec.action_feature_size == 0
    assert spec.action_dim == 2 and (spec.action_low, spec.action_high) == (0.0, 1.0)
    assert spec.horizon == 3 and spec.action_input_size == 2
    state, obs = env.reset(jax.random.PRNGKey(0))
    assert obs.vector.shape == (spec.observation_size,) == (2 * 20 + 3 * 3 + 1,)
    assert obs.action_features.shape == (0, 0) and obs.action_mask.shape == (0,)
    assert obs.action_mask.dtype == jnp.bool_
    np.testing.assert_array_equal(obs.vector[:40], np.asarray(state.clients).reshape(-1))
    assert np.all((np.asarray(state.clients) >= 0) & (np.asarray(state.clients) <= 1))
    assert not np.asarray(obs.vector[40:]).any()  # nothing placed yet, t = 0


def test_observation_shows_the_facilities_placed_so_far(env):
    state, _ = env.reset(jax.random.PRNGKey(1))
    state, obs, _, _ = _place(env, state, [(0.25, 0.75)])
    vector = np.asarray(obs.vector)
    np.testing.assert_allclose(vector[40:46], [0.25, 0.75, 0, 0, 0, 0])
    np.testing.assert_array_equal(vector[46:49], [1, 0, 0])
    assert vector[49] == pytest.approx(1 / 3)


def test_grid_view_counts_the_clients_and_the_cost_they_pay_per_cell():
    env = flp.make(num_clients=4, num_facilities=2, view="grid", grid_size=2)
    assert env.spec.observation_size == 2 * 2 * 2 + 3 * 2 + 1
    clients = [(0.1, 0.1), (0.2, 0.3), (0.9, 0.1), (0.6, 0.9)]  # cells (0, 0) twice, (1, 0), (1, 1)
    state = _state(clients, 2)
    vector = np.asarray(env.step(state, jnp.asarray([0.1, 0.1]))[1].vector)
    share, cost = vector[:4], vector[4:8]
    np.testing.assert_allclose(share, [0.5, 0, 0.25, 0.25])
    distances = np.linalg.norm(np.asarray(clients) - [0.1, 0.1], axis=1)
    expected = np.array([distances[0] + distances[1], 0, distances[2], distances[3]]) / (4 * np.sqrt(2))
    np.testing.assert_allclose(cost, expected, rtol=1e-6)
    np.testing.assert_allclose(vector[8:], [0.1, 0.1, 0, 0, 1, 0, 0.5], rtol=1e-6)


def test_grid_view_before_any_facility_charges_every_client_the_diagonal_and_ignores_client_order():
    env = flp.make(view="grid")
    state, obs = env.reset(jax.random.PRNGKey(3))
    share, cost = np.asarray(obs.vector[:64]), np.asarray(obs.vector[64:128])
    assert share.sum() == pytest.approx(1.0) and np.count_nonzero(share) > 1
    np.testing.assert_allclose(cost, share, rtol=1e-6)  # nothing placed: each client pays sqrt(2)
    shuffled = state._replace(clients=state.clients[::-1])
    for facility in ([0.3, 0.6], [0.9, 0.2]):
        state, obs, _, _ = env.step(state, jnp.asarray(facility))
        shuffled, shuffled_obs, _, _ = env.step(shuffled, jnp.asarray(facility))
        np.testing.assert_allclose(obs.vector, shuffled_obs.vector, atol=1e-6)


@pytest.mark.parametrize(
    "objective, facilities, expected",
    [
        ("max", [(0.5, 0.5)], np.sqrt(0.5)),
        ("mean", [(0.5, 0.5)], np.sqrt(0.5)),
        ("max", [(0.0, 0.0), (1.0, 1.0)], 1.0),
        ("mean", [(0.0, 0.0), (1.0, 1.0)], 0.5),
        ("max", [(0.0, 0.5), (1.0, 0.5), (0.0, 0.0)], 0.5),
        ("mean", [(0.0, 0.5), (1.0, 0.5), (0.0, 0.0)], 0.375),
    ],
)
def test_score_on_a_known_layout(objective, facilities, expected):
    env = flp.make(num_clients=4, num_facilities=len(facilities), objective=objective)
    state, _, rewards, dones = _place(env, _state(SQUARE, len(facilities)), facilities)
    assert dones == [False] * (len(facilities) - 1) + [True]
    assert rewards[:-1] == [0.0] * (len(facilities) - 1)
    assert rewards[-1] == pytest.approx(-expected, abs=1e-6)


def test_episode_metrics_report_both_objectives():
    env = flp.make(num_clients=4, num_facilities=2)
    state, _, _, _ = _place(env, _state(SQUARE, 2), [(0.0, 0.0), (1.0, 1.0)])
    batch = jax.tree_util.tree_map(lambda x: jnp.stack([x, x]), state)
    metrics = env.episode_metrics(batch)
    np.testing.assert_allclose(metrics["covering_radius"], [1.0, 1.0])
    np.testing.assert_allclose(metrics["mean_distance"], [0.5, 0.5])


def test_actions_are_clipped_into_the_unit_square():
    env = flp.make(num_clients=4, num_facilities=3)
    state, _, rewards, _ = _place(env, _state(SQUARE, 3), [(-1.0, 2.0), (0.3, 1.5), (7.0, -0.2)])
    np.testing.assert_allclose(state.facilities, [[0.0, 1.0], [0.3, 1.0], [1.0, 0.0]])
    assert rewards[-1] == pytest.approx(-1.0)  # client (0, 0): 1 from both (0, 1) and (1, 0)


def test_farthest_first_starts_near_the_centroid_and_takes_the_farthest():
    clients = jnp.asarray([(0.0, 0.0), (1.0, 0.0), (0.5, 0.45), (0.5, 1.0)])  # centroid (0.5, 0.3625)
    facilities = flp.farthest_first(clients, 3)
    # (0, 0) and (1, 0) tie as farthest from the start: the first wins; then (1, 0) is farther than (0.5, 1)
    np.testing.assert_allclose(facilities, [(0.5, 0.45), (0.0, 0.0), (1.0, 0.0)])


def test_centres_of_a_square():
    clients = jnp.asarray(SQUARE + [(0.9, 0.9)])
    members = jnp.asarray([1.0, 1.0, 1.0, 1.0, 0.0])  # the fifth client is someone else's
    np.testing.assert_allclose(flp.centroid(clients, members), [0.5, 0.5], atol=1e-6)
    np.testing.assert_allclose(flp.geometric_median(clients, members), [0.5, 0.5], atol=1e-4)
    np.testing.assert_allclose(flp.enclosing_centre(clients, members), [0.5, 0.5], atol=0.05)
    line = jnp.asarray([(0.0, 0.0), (0.1, 0.0), (0.2, 0.0), (1.0, 0.0)])
    assert float(flp.geometric_median(line, jnp.ones(4))[0]) == pytest.approx(0.15, abs=0.05)  # a median, not 0.325
    assert float(flp.enclosing_centre(line, jnp.ones(4))[0]) == pytest.approx(0.5, abs=0.05)


def test_farthest_first_is_within_twice_the_exact_optimum_on_tiny_instances():
    square = np.asarray(SQUARE)
    assert _optimal_radius(square, 1) == pytest.approx(np.sqrt(0.5))
    assert _optimal_radius(square, 2) == pytest.approx(0.5)  # two sides of the square
    rng = np.random.default_rng(0)
    for _ in range(4):
        clients = rng.uniform(size=(6, 2))
        optimal = _optimal_radius(clients, 2)
        radii = {
            name: float(flp.cost(jnp.asarray(clients), facilities[0], "max"))
            for name, facilities in flp.reference_placements(jnp.asarray(clients)[None], 2, "max").items()
        }
        assert radii["farthest_first"] <= 2 * optimal + 1e-5
        assert min(radii.values()) >= optimal - 1e-5  # nothing beats the exact optimum


@pytest.mark.parametrize("name", ["flp", "flp-mean"])
def test_references_are_in_sensible_order(name):
    env = envs.make(name)
    states, _ = jax.vmap(env.reset)(jax.random.split(jax.random.PRNGKey(2), 300))
    out = env.references(states, np.zeros(300))
    assert set(out) == {"farthest_first_score", "kmeans_score", "lloyd_score", "random_score"}
    assert out["random_score"] < out["farthest_first_score"] < out["kmeans_score"] <= out["lloyd_score"] < 0
    assert out["random_score"] == pytest.approx(-0.645 if name == "flp" else -0.322, abs=0.04)


def test_render_draws_clients_facilities_and_the_radius():
    env_max, env_mean = flp.make(num_facilities=2), flp.make(num_facilities=2, objective="mean")
    state, _ = env_max.reset(jax.random.PRNGKey(3))
    state, _, _, _ = _place(env_max, state, [(0.3, 0.3), (0.7, 0.7)])
    colours = lambda image: {tuple(pixel) for pixel in image.reshape(-1, 3)}
    drawn = env_max.render(state)
    assert drawn.shape == (flp.SIZE, flp.SIZE, 3) and drawn.dtype == np.uint8
    assert {flp.FACILITY_COLOUR, flp.CLIENT_COLOUR, flp.LINK_COLOUR, flp.RADIUS_COLOUR} <= colours(drawn)
    assert flp.RADIUS_COLOUR not in colours(env_mean.render(state))
    assert flp.FACILITY_COLOUR not in colours(env_max.render(env_max.reset(jax.random.PRNGKey(3))[0]))


def test_render_joins_each_client_to_its_nearest_facility():
    clients = [(0.1, 0.1), (0.1, 0.3), (0.9, 0.9), (0.7, 0.8)]
    state = FLPState(jnp.asarray(clients), jnp.asarray([(0.2, 0.2), (0.8, 0.8)]), jnp.int32(2))
    image = flp.render(state, objective="mean")
    scale = flp.SIZE - 2 * flp.MARGIN
    pixel = lambda xy: tuple(image[round(flp.SIZE - flp.MARGIN - xy[1] * scale), round(flp.MARGIN + xy[0] * scale)])
    between = lambda a, b, f: (a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]))
    for client, facility in zip(clients, [(0.2, 0.2), (0.2, 0.2), (0.8, 0.8), (0.8, 0.8)]):
        assert {pixel(between(client, facility, f)) for f in (0.4, 0.5, 0.6)} == {flp.LINK_COLOUR}
    assert pixel(between(clients[0], (0.8, 0.8), 0.5)) == (255, 255, 255)  # no link to the farther facility


@pytest.mark.parametrize(
    "name, args, named",
    [
        ("flp", {"num_facilities": 0}, "num_facilities must be an integer in 1..20, got 0"),
        ("flp", {"num_clients": 5, "num_facilities": 6}, "num_facilities must be an integer in 1..5, got 6"),
        ("flp-mean", {"num_clients": 0}, "num_clients must be an integer at least 1, got 0"),
        ("flp", {"num_facilities": 2.0}, "got 2.0"),
        ("flp-mean", {"num_facilities": 0}, "flp-mean: num_facilities must be an integer in 1..20, got 0"),
        ("flp", {"num_clients": "20"}, "flp: num_clients must be an integer at least 1, got '20'"),
        ("flp", {"objective": "mean"}, "bad parameters for environment 'flp'"),
        ("flp", {"view": "image"}, "flp: view must be one of flat, grid, got 'image'"),
        ("flp-mean", {"grid_size": 0}, "flp-mean: grid_size must be an integer at least 1, got 0"),
    ],
)
def test_bad_parameters_are_one_line_errors(name, args, named):
    with pytest.raises(ValueError, match=named) as error:
        envs.make(name, **args)
    assert "\n" not in str(error.value)
    with pytest.raises(ValueError, match="objective must be one of max, mean, got 'median'"):
        flp.make(objective="median")


def test_eval_and_render_from_the_cli(tmp_path, capsys):
    """A run dir without checkpoints holds the untrained agent: enough for the CLI's env paths, no Ray."""
    from pizero_ray.cli import main
    from pizero_ray.config import build_config
    from pizero_ray.storage import run_dir

    path = tmp_path / "run"
    run_dir.write_config(path, build_config("tiny", env="flp-mean", planner="none"))  # the cheapest agent to compile
    assert main(["eval", str(path), "--episodes", "16", "--json"]) == 0
    evaluation = json.loads(capsys.readouterr().out)
    assert evaluation["env"] == "flp-mean" and evaluation["mean_score"] < 0
    assert evaluation["random_score"] < evaluation["lloyd_score"]
    assert evaluation["mean_mean_distance"] == pytest.approx(-evaluation["mean_score"], rel=1e-5)
    assert evaluation["mean_covering_radius"] > evaluation["mean_mean_distance"]
    png = tmp_path / "final.png"
    assert main(["render", str(path), "--out", str(png)]) == 0
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
