"""A baseline's learner: its planning loss learns, and checkpoint and resume change nothing."""

import functools

import jax
import jax.numpy as jnp
import numpy as np
import optax

from pizero_ray import envs
from pizero_ray.baselines import losses, make_learner, replay
from pizero_ray.baselines.networks import make_model
from pizero_ray.config import build_config
from pizero_ray.storage import checkpoints, runs
from pizero_ray.storage import run_dir as rundir


def random_episodes(env, key, num_episodes: int) -> replay.Episodes:
    """Episodes of uniformly random moves, each step's policy target a random distribution (no search)."""
    states, observations = jax.vmap(env.reset)(jax.random.split(key, num_episodes))

    def step(carry, t):
        states, observations, done = carry
        step_key = jax.random.fold_in(key, t)
        action = jax.random.randint(step_key, (num_episodes,), 0, env.spec.num_actions)
        policy = jax.nn.softmax(jax.random.normal(jax.random.fold_in(step_key, 1), (num_episodes, 4)))
        states, next_observations, reward, step_done = jax.vmap(env.step)(states, action)
        record = replay.Episodes(observations, action, policy, jnp.where(done, 0.0, reward), ~done)
        return (states, next_observations, done | step_done), record

    carry = (states, observations, jnp.zeros((num_episodes,), bool))
    recorded = jax.lax.scan(step, carry, jnp.arange(env.spec.horizon))[1]
    return jax.tree_util.tree_map(lambda x: jnp.swapaxes(x, 0, 1), recorded)


def test_the_muzero_unroll_loss_decreases_on_a_fixed_batch():
    config = build_config("tiny", env="collect", method="muzero", hidden_size=32, latent_size=16)
    env = envs.make("collect", horizon=8)

    @jax.jit  # one program, not one per operation
    def fixed_batch(key):
        played = random_episodes(env, key, num_episodes=8)
        buffer = replay.replay_add(replay.replay_init(played, 8), played)
        return replay.replay_sample(buffer, jax.random.fold_in(key, 1), batch_size=64, unroll=config.unroll_steps)

    batch = fixed_batch(jax.random.PRNGKey(1))
    assert batch.policy.shape[1] == 6  # the root and 5 unrolled steps
    assert not bool(batch.policy_valid.all())  # some unrolls run past the end: absorbing targets are in the loss
    model = make_model(config, env.spec)
    params = model.init(jax.random.PRNGKey(0))
    loss = functools.partial(losses.muzero_loss, model)
    optimizer = optax.adam(3e-3)

    @jax.jit
    def fit(params):
        def step(carry, _):
            params, state = carry
            (value, parts), grads = jax.value_and_grad(lambda p: loss(p, batch), has_aux=True)(params)
            updates, state = optimizer.update(grads, state, params)
            return (optax.apply_updates(params, updates), state), (value, parts["reward_loss"])

        return jax.lax.scan(step, (params, optimizer.init(params)), None, length=150)[1]

    values, reward_losses = fit(params)
    assert float(values[-1]) < 0.6 * float(values[0])
    assert float(reward_losses[-1]) < 0.5 * float(reward_losses[0])  # the dynamics learns the rewards too


def test_checkpoint_and_resume_give_the_parameters_of_an_uninterrupted_run(tmp_path):
    config = build_config("tiny", method="muzero", selfplay_episodes=4, batch_size=16, replay_size=8,
                          updates_per_iteration=2)
    learner = make_learner(config, envs.make("tsp", num_cities=5))
    straight = learner.init()
    for _ in range(4):
        straight, _ = learner.iterate(straight)

    rundir.write_config(tmp_path, config)
    state = learner.init()
    for _ in range(2):
        state, _ = learner.iterate(state)
    writer = checkpoints.CheckpointWriter(tmp_path)
    runs.save(writer, config, state)  # parameters, Adam state and the replay buffer
    writer.close()
    resumed, _ = runs.restore(tmp_path, learner.init())
    assert resumed.iteration == 2 and int(resumed.replay.filled) == 8
    for _ in range(2):
        resumed, _ = learner.iterate(resumed)
    assert resumed.iteration == straight.iteration == 4
    assert runs.parameter_hash(np.asarray(resumed.theta)) == runs.parameter_hash(np.asarray(straight.theta))
    assert runs.parameter_hash(np.asarray(straight.theta)) != runs.parameter_hash(np.asarray(learner.init().theta))
