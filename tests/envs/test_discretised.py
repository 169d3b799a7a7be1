"""FLP's continuous actions through a grid, as the baselines see them."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from pizero_ray import envs
from pizero_ray.envs.discretised import discretise, grid_points


def test_grid_points_are_cell_centres():
    points = np.asarray(grid_points(4, 2, 0.0, 1.0))
    assert points.shape == (16, 2)
    np.testing.assert_allclose(points[:4], [[0.125, 0.125], [0.125, 0.375], [0.125, 0.625], [0.125, 0.875]])


def test_a_grid_action_places_the_facility_at_its_point():
    flp = envs.make("flp")
    grid = discretise(flp, 16)
    assert grid.spec.discrete and grid.spec.num_actions == 256 and grid.spec.action_feature_size == 2
    assert grid.spec.horizon == flp.spec.horizon and grid.name == "flp"
    state, observation = grid.reset(jax.random.PRNGKey(0))
    assert observation.action_features.shape == (256, 2) and bool(observation.action_mask.all())
    action = 16 * 3 + 10  # row 3, column 10 of the grid
    point = jnp.asarray([3.5 / 16, 10.5 / 16])
    after, _, reward, _ = grid.step(state, jnp.int32(action))
    same, _, same_reward, _ = flp.step(state, point)
    np.testing.assert_allclose(np.asarray(after.facilities), np.asarray(same.facilities), atol=1e-6)
    assert float(reward) == float(same_reward)


def test_only_continuous_environments_are_discretised():
    with pytest.raises(ValueError, match="tsp: action space must be continuous"):
        discretise(envs.make("tsp"), 16)
    with pytest.raises(ValueError, match="points_per_dim must be an integer at least 1, got 0"):
        discretise(envs.make("flp"), 0)
