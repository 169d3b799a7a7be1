"""The Ray driver: owns the parameters and the optimiser state, farms out chunks.

Each iteration: derive the iteration seed from (run seed, iteration), put the
parameters in the object store once, queue the chunks of pair indices, let
worker actors pull them, gather scores [n, 2] in chunk order, regenerate the
noise here to form the pseudo-gradient, and take an Adam step. Only a seed, an
object reference and a chunk index go out; only scores come back.
"""

from __future__ import annotations

import hashlib
import json
import time
from collections import deque
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, NamedTuple

import numpy as np

from pizero_ray import checkpoints, compile_cache
from pizero_ray import run_dir as rundir
from pizero_ray.config import Config, ConfigError

EVAL_SEED = 2_000_003  # fixed held-out episodes for the learning curve


@dataclass(frozen=True)
class RunOptions:
    """How to run (not what to compute): none of this changes the parameters."""

    iterations: int
    workers: int = 2
    cpus_per_worker: float = 1.0
    gpus_per_worker: float = 0.0
    address: str | None = None
    checkpoint_every: int = 25
    keep_checkpoints: int = 3
    eval_every: int = 0
    eval_episodes: int = 256
    chunk_timeout_s: float = 900.0  # generous: a worker's first chunk includes its compile
    in_flight_per_worker: int = 2  # keeps a worker busy while its last result travels
    compile_cache: str | None = str(compile_cache.DEFAULT_DIR)


class TrainingError(RuntimeError):
    pass


def parameter_hash(theta: np.ndarray) -> str:
    return hashlib.sha256(np.ascontiguousarray(theta, dtype="<f4").tobytes()).hexdigest()


class WorkerPool:
    """Worker actors plus a queue of chunks; a chunk whose worker dies is re-queued."""

    def __init__(self, config: Config, options: RunOptions):
        from pizero_ray import workers

        self._config = config
        self._options = options
        config_json = config.to_json()
        self.actors = [
            workers.start_worker(config_json, options.cpus_per_worker, options.gpus_per_worker, options.compile_cache)
            for _ in range(options.workers)
        ]

    def evaluate(self, theta_ref, seed: int) -> np.ndarray:
        import ray
        from ray.exceptions import RayActorError

        chunk = self._config.chunk_size
        pending = deque(range(self._config.num_chunks))
        results: dict[int, np.ndarray] = {}
        in_flight: dict = {}  # ObjectRef -> (chunk index, actor)
        load = {id(actor): 0 for actor in self.actors}
        while len(results) < self._config.num_chunks:
            for actor in list(self.actors):
                while pending and load[id(actor)] < self._options.in_flight_per_worker:
                    index = pending.popleft()
                    ref = actor.evaluate_chunk.remote(theta_ref, seed, index * chunk)
                    in_flight[ref] = (index, actor)
                    load[id(actor)] += 1
            if not in_flight:
                raise TrainingError("no live workers left to evaluate the remaining chunks")
            ready, _ = ray.wait(list(in_flight), num_returns=1, timeout=self._options.chunk_timeout_s)
            if not ready:
                raise TrainingError(f"no chunk finished within {self._options.chunk_timeout_s:.0f} s")
            for ref in ready:
                index, actor = in_flight.pop(ref)
                load[id(actor)] -= 1
                try:
                    results[index] = ray.get(ref)
                except RayActorError:
                    # The worker died: its chunk goes back on the queue and runs elsewhere.
                    pending.appendleft(index)
                    if actor in self.actors:
                        self.actors.remove(actor)
        return np.concatenate([results[i] for i in range(self._config.num_chunks)])

    def shutdown(self) -> None:
        import ray

        for actor in self.actors:
            ray.kill(actor)
        self.actors = []


def _initial_state(config: Config, env):
    import jax.numpy as jnp

    from pizero_ray import es, rollout

    theta, layout = rollout.flat_params(config, env)
    optimizer, update = es.make_update(config, layout.size)
    return np.asarray(theta), optimizer.init(jnp.asarray(theta)), layout, update


class LoadedRun(NamedTuple):
    config: Config
    iteration: int
    theta: np.ndarray  # flat parameters
    env: object  # envs.Environment
    layout: object  # rollout.FlatParams


def load_run(run_path: Path, env_args: dict | None = None) -> LoadedRun:
    """A run dir's newest checkpoint (or its initial parameters), with its environment.

    ``env_args`` override the run's environment parameters (evaluate on other
    levels, say); they may not change the agent's shape.
    """
    import envs

    config = rundir.read_config(run_path)
    trained_env = envs.make(config.env, **config.env_kwargs())
    theta, opt_state, layout, _ = _initial_state(config, trained_env)
    env = trained_env
    if env_args:
        try:
            env = envs.make(config.env, **{**config.env_kwargs(), **env_args})
        except ValueError as error:
            raise ConfigError(str(error)) from None
        if env.spec != trained_env.spec:
            raise ConfigError(f"env args {env_args} change the environment's shapes: the trained agent cannot act")
    restored = checkpoints.restore_latest(run_path, theta, opt_state)
    if restored is None:
        return LoadedRun(config, 0, theta, env, layout)
    return LoadedRun(config, restored.iteration, restored.theta, env, layout)


def train(
    run_path: Path,
    config: Config,
    options: RunOptions,
    on_iteration: Callable[[dict], None] | None = None,
    on_start: Callable[[dict], None] | None = None,
) -> dict:
    """Trains until ``options.iterations`` iterations are done, resuming from the newest checkpoint."""
    import jax
    import jax.numpy as jnp
    import ray

    import envs
    from pizero_ray import es, ray_setup, rollout

    # Ray first: it forks its processes before JAX starts its threads.
    connection = ray_setup.init(options.address, num_cpus=None)
    compile_cache.enable(options.compile_cache)
    env = envs.make(config.env, **config.env_kwargs())
    theta, opt_state, layout, update = _initial_state(config, env)
    start_iteration = 0
    restored = checkpoints.restore_latest(run_path, theta, opt_state)
    if restored is not None:
        start_iteration, theta, opt_state = restored.iteration, restored.theta, restored.opt_state
    metrics = [row for row in rundir.read_metrics(run_path) if row["iteration"] <= start_iteration]
    _rewrite_metrics(run_path, metrics)
    wall_offset = metrics[-1]["wall_time_s"] if metrics else 0.0

    evaluator = None
    if options.eval_every > 0:
        evaluator = rollout.make_evaluator(config, env, layout, options.eval_episodes)

    pool = WorkerPool(config, options)
    writer = checkpoints.CheckpointWriter(run_path, options.keep_checkpoints)
    log = rundir.MetricsLog(run_path)
    theta_device = jnp.asarray(theta)
    iteration = start_iteration

    def save() -> None:
        meta = {"iteration": iteration, "seed": config.seed, "config": json.loads(config.to_json()),
                "metrics_rows": iteration, "parameter_hash": parameter_hash(np.asarray(theta_device))}
        writer.save(iteration, np.asarray(theta_device), opt_state, meta)

    if on_start:
        on_start({"connection": connection, "start_iteration": start_iteration, "parameters": layout.size,
                  "workers": len(pool.actors)})
    started = time.time()
    try:
        if evaluator is not None and not metrics:
            # Row 0: the untrained agent, so every learning curve has its starting point.
            eval_scores = evaluator(theta_device, jax.random.PRNGKey(EVAL_SEED))
            log.write({"iteration": 0, "eval_mean_score": float(eval_scores.mean()), "wall_time_s": 0.0})
        while iteration < options.iterations:
            t0 = time.time()
            seed = es.iteration_seed(config.seed, iteration)
            theta_ref = ray.put(np.asarray(theta_device))  # once per iteration; each node fetches it once
            scores = pool.evaluate(theta_ref, seed)
            t1 = time.time()
            theta_device, opt_state, stats = update(theta_device, opt_state, np.uint32(seed), jnp.asarray(scores))
            theta_device.block_until_ready()
            iteration += 1
            now = time.time()
            row = {
                "iteration": iteration,
                "mean_score": float(scores.mean()),
                "std_score": float(scores.std()),
                "max_score": float(scores.max()),
                "min_score": float(scores.min()),
                "iteration_time_s": now - t0,
                "update_time_s": now - t1,
                "wall_time_s": wall_offset + now - started,
                "gradient_norm": float(stats.gradient_norm),
                "parameter_norm": float(stats.parameter_norm),
                "workers": len(pool.actors),
            }
            if evaluator is not None and (iteration % options.eval_every == 0 or iteration == options.iterations):
                eval_scores = evaluator(theta_device, jax.random.PRNGKey(EVAL_SEED))
                row["eval_mean_score"] = float(eval_scores.mean())
            log.write(row)
            if options.checkpoint_every > 0 and iteration % options.checkpoint_every == 0:
                save()
            if on_iteration:
                on_iteration(row)
        save()
    finally:
        log.close()
        writer.close()
        pool.shutdown()
    theta = np.asarray(theta_device)
    return {"iteration": iteration, "parameter_hash": parameter_hash(theta)}


def _rewrite_metrics(run_path: Path, rows: list[dict]) -> None:
    """Keeps exactly the rows up to the restored iteration (atomic replace)."""
    path = run_path / rundir.METRICS_FILE
    tmp = path.with_suffix(".jsonl.tmp")
    tmp.write_text("".join(json.dumps(row, sort_keys=True) + "\n" for row in rows))
    tmp.replace(path)
