import jax
import jax.numpy as jnp
import numpy as np

from pizero_ray.agent import networks


def test_a_low_rank_perturbed_matrix_acts_as_the_formed_matrix():
    base = jax.random.normal(jax.random.PRNGKey(0), (5, 3))
    left = jax.random.normal(jax.random.PRNGKey(1), (2, 5))
    right = jax.random.normal(jax.random.PRNGKey(2), (2, 3))
    x = jax.random.normal(jax.random.PRNGKey(3), (4, 5))
    formed = x @ (base + left.T @ right)
    np.testing.assert_allclose(networks.linear(x, networks.LowRankPerturbed(base, left, right)), formed, rtol=1e-5)
    np.testing.assert_array_equal(networks.linear(x, base), x @ base)


def test_dense_init_is_lecun_normal_with_zero_bias():
    params = networks.dense_init(jax.random.PRNGKey(0), 400, 300)
    assert params["w"].shape == (400, 300) and not np.asarray(params["b"]).any()
    np.testing.assert_allclose(float(jnp.std(params["w"])), 1 / np.sqrt(400), rtol=0.02)


def test_mlp_has_tanh_hidden_layers_a_linear_output_and_any_leading_dims():
    params = networks.mlp_init(jax.random.PRNGKey(0), (3, 16, 2))
    params["layer1"]["b"] = params["layer1"]["b"] + 10.0  # a linear output is not squashed
    x = jax.random.normal(jax.random.PRNGKey(1), (4, 7, 3))
    out = networks.mlp(params, x)
    assert out.shape == (4, 7, 2) and float(out.min()) > 1.0
    hidden = jnp.tanh(x @ params["layer0"]["w"] + params["layer0"]["b"])
    np.testing.assert_allclose(out, hidden @ params["layer1"]["w"] + params["layer1"]["b"], rtol=1e-5)


def test_gru_keeps_its_state_when_the_update_gate_is_shut():
    params = networks.gru_init(jax.random.PRNGKey(0), 2, 4)
    hidden = jnp.array([[0.5, -0.25, 0.0, 0.9]])
    x = jnp.array([[1.0, -1.0]])
    out = networks.gru(params, hidden, x)
    assert out.shape == (1, 4) and float(jnp.abs(out).max()) < 1.0
    assert not np.allclose(out, hidden)
    # Bias the update gate (the middle third) far open: z = 1 keeps the old state.
    shut = {"input": {**params["input"], "b": params["input"]["b"].at[4:8].set(100.0)}, "hidden": params["hidden"]}
    np.testing.assert_allclose(networks.gru(shut, hidden, x), hidden, atol=1e-6)
