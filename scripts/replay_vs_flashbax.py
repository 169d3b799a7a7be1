"""The baselines' replay work per iteration, the project's ring buffer against flashbax's trajectory buffer.

One iteration's worth at the defaults: add 32 episodes, then 8 samples of 128
positions (unroll 0: AlphaZero; 5: MuZero), jitted, median of 30 calls, on
made-up episodes shaped like each environment's. Flashbax is not a dependency
of the project; install it beside it, without touching the venv:

    .venv/bin/pip install --target /tmp/fbx --no-deps flashbax==0.1.3 flax treescope
    PYTHONPATH=/tmp/fbx JAX_PLATFORMS=cpu .venv/bin/python scripts/replay_vs_flashbax.py tsp sokoban 2048

Flashbax's sampled sequences are not the same thing: they run across
episode ends and into padding, so a MuZero target would need masking on top.
Its value targets are computed once at add time; the ring buffer computes
them at sampling.
"""
import json
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import flashbax as fbx  # noqa: E402
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402

import envs  # noqa: E402
from pizero_ray.baselines import replay  # noqa: E402

EPISODES, CAPACITY, UPDATES, BATCH = 32, 256, 8, 128  # the baselines' defaults


def made_up_episodes(env, key) -> replay.Episodes:
    _, observation = jax.vmap(env.reset)(jax.random.split(key, EPISODES))
    horizon, actions = env.spec.horizon, env.spec.num_actions
    observations = jax.tree_util.tree_map(
        lambda x: jnp.broadcast_to(x[:, None], (EPISODES, horizon) + x.shape[1:]), observation)
    action_key, policy_key = jax.random.split(key)
    return replay.Episodes(observations, jax.random.randint(action_key, (EPISODES, horizon), 0, actions),
                           jax.nn.softmax(jax.random.normal(policy_key, (EPISODES, horizon, actions))),
                           jax.random.uniform(action_key, (EPISODES, horizon)), jnp.ones((EPISODES, horizon), bool))


def median_ms(iteration, state, episodes, calls: int = 30) -> float:
    key = jax.random.PRNGKey(0)
    state, out = iteration(state, episodes, key)  # compiles
    jax.block_until_ready(out)
    times = []
    for i in range(calls):
        start = time.perf_counter()
        state, out = iteration(state, episodes, jax.random.fold_in(key, i))
        jax.block_until_ready((state, out))
        times.append(time.perf_counter() - start)
    return 1e3 * statistics.median(times)


def ring_buffer_ms(episodes, unroll: int) -> float:
    def iteration(buffer, episodes, key):
        buffer = replay.replay_add(buffer, episodes)
        batches = [replay.replay_sample(buffer, jax.random.fold_in(key, u), BATCH, unroll) for u in range(UPDATES)]
        return buffer, sum(jnp.sum(batch.value) for batch in batches)

    return median_ms(jax.jit(iteration, donate_argnums=0), replay.replay_init(episodes, CAPACITY), episodes)


def flashbax_ms(episodes, unroll: int, horizon: int) -> float:
    buffer = fbx.make_trajectory_buffer(
        add_batch_size=EPISODES, sample_batch_size=BATCH, sample_sequence_length=unroll + 1, period=1,
        min_length_time_axis=unroll + 1, max_length_time_axis=CAPACITY // EPISODES * horizon)

    def steps(e):  # one record per step, the return to go computed once, at add time
        return {"observation": e.observation, "action": e.action, "policy": e.policy, "reward": e.reward,
                "valid": e.valid, "value": replay.returns_to_go(e.reward)}

    def iteration(state, episodes, key):
        state = buffer.add(state, steps(episodes))
        samples = [buffer.sample(state, jax.random.fold_in(key, u)) for u in range(UPDATES)]
        return state, sum(jnp.sum(sample.experience["value"]) for sample in samples)

    state = buffer.init(jax.tree_util.tree_map(lambda x: x[0, 0], steps(episodes)))
    return median_ms(jax.jit(iteration, donate_argnums=0), state, episodes)


if __name__ == "__main__":
    for name in sys.argv[1:] or ["tsp", "sokoban", "2048"]:
        env = envs.make(name)
        episodes = made_up_episodes(env, jax.random.PRNGKey(1))
        for unroll in (0, 5):
            print(json.dumps({"env": name, "unroll": unroll, "horizon": env.spec.horizon,
                              "ring_buffer_ms": round(ring_buffer_ms(episodes, unroll), 2),
                              "flashbax_ms": round(flashbax_ms(episodes, unroll, env.spec.horizon), 2)}), flush=True)
