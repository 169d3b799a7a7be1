"""The Ray driver: owns the parameters and the optimiser state, farms out chunks.

Each iteration: derive the iteration seed from (run seed, iteration), put the
parameters in the object store once, let the worker pool evaluate the queue of
chunks of pair indices, turn the scores into per-pair weights, collect each
chunk's share of the pseudo-gradient from the worker that still holds the
chunk's noise (or regenerate it here), add the shares in chunk order and take
an Adam step. Only a seed, an object reference and a chunk index go out for a
chunk, scores come back; then a chunk's weights go out and its share (one
vector) comes back. Checkpoints every K iterations and on exit, SIGTERM or
SIGINT.
"""

from __future__ import annotations

import functools
import json
import signal
import threading
import time
from pathlib import Path
from typing import Callable

import numpy as np

from pizero_ray.config import Config
from pizero_ray.storage import checkpoints, runs
from pizero_ray.storage import run_dir as rundir
from pizero_ray.trainer import compile_cache
from pizero_ray.trainer.options import RunOptions
from pizero_ray.trainer.pool import Interrupted, TrainingError, WorkerPool

EVAL_SEED = 2_000_003  # fixed held-out episodes for the learning curve

__all__ = ["RunOptions", "TrainingError", "train"]


class _StopRequest:
    """SIGTERM/SIGINT set a flag; the loop saves and leaves at the next look-up (<= 0.5 s)."""

    def __init__(self):
        self.signal: int | None = None
        self._previous = {}

    def __enter__(self):
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGTERM, signal.SIGINT):
                self._previous[sig] = signal.signal(sig, self._handle)
        return self

    def _handle(self, signum, frame):
        if self.signal is not None:  # a second signal: stop waiting for the save
            raise KeyboardInterrupt
        self.signal = signum

    def __call__(self) -> bool:
        return self.signal is not None

    def __exit__(self, *exc):
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)


def train(
    run_path: Path,
    config: Config,
    options: RunOptions,
    on_iteration: Callable[[dict], None] | None = None,
    on_start: Callable[[dict], None] | None = None,
) -> dict:
    """Trains until ``options.iterations`` iterations are done, resuming from the newest good checkpoint.

    Returns {"iteration", "parameter_hash", "stopped_by"}: ``stopped_by`` names
    the signal that interrupted training (after a checkpoint was saved), or None.
    """
    import jax
    import jax.numpy as jnp
    import ray

    import envs
    from pizero_ray import es
    from pizero_ray.agent import episodes
    from pizero_ray.trainer import ray_setup

    # Ray first: it forks its processes before JAX starts its threads.
    connection = ray_setup.init(options.address)
    compile_cache.enable(options.pool.compile_cache)
    env = envs.make(config.env, **config.env_kwargs())
    theta, opt_state, layout, update = runs.initial_state(config, env)
    # Refuses a run dir whose progress it cannot continue (unless options.restart); never deletes a metrics row.
    start_iteration, theta, opt_state, metrics = checkpoints.prepare_resume(run_path, theta, opt_state,
                                                                           restart=options.restart)
    wall_offset = metrics[-1]["wall_time_s"] if metrics else 0.0

    evaluator = None
    if options.eval_every > 0:
        evaluator = episodes.make_evaluator(config, env, layout.unravel, options.eval_episodes)

    pool = WorkerPool(config, options.pool)
    writer = checkpoints.CheckpointWriter(run_path, options.keep_checkpoints)
    log = rundir.MetricsLog(run_path)
    theta_device = jnp.asarray(theta)
    iteration = start_iteration

    def save() -> None:
        host_theta = np.asarray(theta_device)
        meta = {"iteration": iteration, "seed": config.seed, "config": json.loads(config.to_json()),
                "metrics_rows": iteration, "parameter_hash": runs.parameter_hash(host_theta)}
        writer.save(iteration, host_theta, opt_state, meta)

    if on_start:
        on_start({"connection": connection, "start_iteration": start_iteration, "parameters": layout.size,
                  "workers": options.pool.workers})
    started = time.time()
    stop = _StopRequest()
    try:
        with stop:
            if iteration == 0:
                save()  # a run killed before its first periodic checkpoint still resumes (prepare_resume)
            if evaluator is not None and not metrics:
                # Row 0: the untrained agent, so every learning curve has its starting point.
                eval_scores = evaluator(theta_device, jax.random.PRNGKey(EVAL_SEED))
                log.write({"iteration": 0, "eval_mean_score": float(eval_scores.mean()), "wall_time_s": 0.0})
            while iteration < options.iterations and not stop():
                t0 = time.time()
                seed = es.iteration_seed(config.seed, iteration)
                theta_ref = ray.put(np.asarray(theta_device))  # once per iteration; each node fetches it once
                try:
                    result = pool.evaluate(theta_ref, seed, iteration, should_stop=stop)
                except Interrupted:
                    break  # the unfinished iteration is dropped; the last finished one is saved below
                t1 = time.time()
                weights, num_pairs = update.weights(jnp.asarray(result.scores), jnp.asarray(result.valid))
                weights = np.asarray(weights)
                try:
                    parts, parts_here = pool.gradient_parts(
                        seed, weights, result.owners, functools.partial(update.part_here, seed, weights),
                        should_stop=stop)
                except Interrupted:
                    break  # as above: theta is still the last finished iteration's, saved below
                theta_device, opt_state, stats = update.step(
                    theta_device, opt_state, es.GradientParts.total(parts), num_pairs)
                theta_device.block_until_ready()
                iteration += 1
                now = time.time()
                scores = result.scores[result.valid]
                row = {
                    "iteration": iteration,
                    "mean_score": float(scores.mean()),
                    "std_score": float(scores.std()),
                    "max_score": float(scores.max()),
                    "min_score": float(scores.min()),
                    "pairs_evaluated": int(result.valid.sum()),
                    "requeued_chunks": result.requeued_chunks,
                    "gradient_parts_on_driver": parts_here,
                    "iteration_time_s": now - t0,
                    "update_time_s": now - t1,
                    "wall_time_s": wall_offset + now - started,
                    "gradient_norm": float(stats.gradient_norm),
                    "parameter_norm": float(stats.parameter_norm),
                    "workers": pool.live_workers,
                    "worker_nodes": [node[:12] for node in result.worker_nodes],
                }
                if result.new_worker_first_result_s:
                    row["new_worker_first_result_s"] = [round(s, 3) for s in result.new_worker_first_result_s]
                if evaluator is not None and (iteration % options.eval_every == 0 or iteration == options.iterations):
                    eval_scores = evaluator(theta_device, jax.random.PRNGKey(EVAL_SEED))
                    row["eval_mean_score"] = float(eval_scores.mean())
                log.write(row)
                if options.checkpoint_every > 0 and iteration % options.checkpoint_every == 0:
                    save()
                if on_iteration:
                    on_iteration(row)
            save()  # on normal exit and on SIGTERM/SIGINT alike
    finally:
        log.close()
        writer.close()
        pool.shutdown()
    stopped_by = signal.Signals(stop.signal).name if stop.signal is not None else None
    return {"iteration": iteration, "parameter_hash": runs.parameter_hash(np.asarray(theta_device)),
            "stopped_by": stopped_by, "workers_killed": pool.kills}
