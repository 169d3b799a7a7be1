"""The Ray driver: owns the parameters and the optimiser state, farms out chunks.

Each iteration (``_Run.iterate``): ask the ES strategy for the iteration
seed (a function of the run seed and the iteration), put the parameters in
the object store once, let the worker pool score the queue of chunks of
pair indices, turn the scores into per-pair weights, collect each chunk's
share of the pseudo-gradient from the worker that still holds the chunk's
noise (or regenerate it here), and tell the strategy the shares: it adds
them in chunk order and takes an Adam step. Only a seed, an object reference
and a chunk index go out for a chunk, scores come back; then a chunk's
weights go out and its share (one vector) comes back. Checkpoints every K iterations and on exit, SIGTERM or
SIGINT.
"""

from __future__ import annotations

import functools
import logging
import math
import signal
import threading
import time
from pathlib import Path
from typing import Callable

import numpy as np

from pizero_ray import methods
from pizero_ray.config import Config
from pizero_ray.evaluation.runs import EVAL_SEED
from pizero_ray.storage import checkpoints, runs, tensorboard, writer_lock
from pizero_ray.storage import run_dir as rundir
from pizero_ray.trainer import compile_cache
from pizero_ray.trainer.options import RunOptions
from pizero_ray.trainer.pool import Interrupted, TrainingError, WorkerPool

_log = logging.getLogger(__name__)

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


class _Run:
    """One training session: the ES state and strategy, the pool, and where the run is written."""

    def __init__(self, run_path: Path, config: Config, options: RunOptions, worker_factory=None):
        from pizero_ray.agent import episodes

        self.config, self.options = config, options
        if not options.restart:
            runs.check_same_config(run_path, config)  # a run never mixes two configurations
        env = methods.make_env(config)
        state, self.layout, self.method = methods.initial_state(config, env)  # ES strategy, or a baseline's Learner
        if config.init_from and (options.restart or not checkpoints.checkpoint_steps(run_path)):
            # Then saved as checkpoint 0. Whoever gave this config named its environment: that one is trusted.
            state = methods.warm_start(state, self.layout, Path(config.init_from), trust_env=config.env)
        self.state, self.metrics = runs.restore(run_path, state, restart=options.restart)
        self.start_iteration = self.state.iteration
        self.held_out = self.plan_use = None
        if options.eval_every > 0 or options.eval_every_minutes is not None:
            eval_env = methods.other_env(config, env, dict(options.eval_env_args))
            agent = methods.acting_agent(config, eval_env, self.method if eval_env is env else None)
            self.held_out = episodes.make_scorer(agent, eval_env, self.layout.unravel, options.eval_episodes)
            self.plan_use = _plan_use_scorers(config, eval_env, self.layout.unravel, options.eval_episodes)
        # The gradient-trained baselines learn in this process; ES farms its population out to the pool.
        self.pool = None if config.gradient_trained else WorkerPool(config, options.pool, worker_factory)
        self.writer = checkpoints.CheckpointWriter(run_path, options.keep_checkpoints)
        self.log = rundir.MetricsLog(run_path)
        self.events = tensorboard.EventLog(run_path)  # mirrors the metrics for tensorboard --logdir
        self.wall_offset = self.metrics[-1]["wall_time_s"] if self.metrics else 0.0
        self.started = time.time()
        self.evaluating_s = 0.0  # the learning curve's evaluations are measurement, not training time
        self.next_eval_s = _next_multiple(self.wall_offset, options.eval_every_minutes)
        self.finished = False  # the iterations or the budget reached (record decides, once per iteration)

    def save(self) -> None:
        runs.save(self.writer, self.config, self.state)

    def evaluate(self) -> dict:
        """The learning curve's evaluation on the held-out episodes: the agent's mean score and, for an agent
        that plans, what its plan is worth (``_plan_use_scorers``)."""
        import jax

        started = time.time()
        key = jax.random.PRNGKey(EVAL_SEED)
        found = {"eval_mean_score": float(self.held_out(self.state.theta, key).mean())}
        if self.plan_use is not None:
            watched, shuffled = self.plan_use
            found["eval_plan_actions_changed"] = float(watched(self.state.theta, key)[1])
            found["eval_plan_shuffled_score"] = float(shuffled(self.state.theta, key).mean())
        self.evaluating_s += time.time() - started
        return found

    def wall_time_s(self) -> float:
        """Training wall-clock of the whole run (this session's after what the metrics held), without evaluations.

        Worker start-up, compiles, checkpoints and stragglers count: they are
        what training costs. The learning curve's evaluations do not (a
        planner's cost more and would tilt an equal-time comparison).
        """
        return self.wall_offset + time.time() - self.started - self.evaluating_s

    def out_of_time(self, wall_time_s: float) -> bool:
        """The budget is spent at training wall-clock ``wall_time_s``."""
        return self.options.minutes is not None and wall_time_s >= 60.0 * self.options.minutes

    def reached_iterations(self) -> bool:
        return self.options.iterations is not None and self.state.iteration >= self.options.iterations

    def begin(self) -> None:
        if self.state.iteration == 0:
            self.save()  # a run killed before its first periodic checkpoint still resumes (prepare_resume)
        if self.held_out is not None and not self.metrics:
            # Row 0: the untrained agent, so every learning curve has its starting point.
            self.write({"iteration": 0, **self.evaluate(), "wall_time_s": 0.0})

    def iterate(self, stop: Callable[[], bool]) -> dict:
        """One iteration of the run's method; raises Interrupted on a stop (ES)."""
        return self._learn() if self.pool is None else self._evolve(stop)

    def _learn(self) -> dict:
        """A baseline's iteration: self-play, replay, Adam steps (one jitted call)."""
        started = time.time()
        state, stats = self.method.iterate(self.state)
        state.theta.block_until_ready()
        losses = {"loss": stats.loss, **stats.parts}
        broken = [name for name, value in (("the self-play score", stats.mean_score), *losses.items())
                  if not np.isfinite(float(value))]
        if broken:  # a NaN reward or loss would be in the parameters from now on: stop before keeping them
            raise TrainingError(f"iteration {state.iteration}: {', '.join(broken)} is not finite "
                                f"(mean self-play score {float(stats.mean_score)}); check the environment's rewards")
        self.state = state
        return {"iteration": state.iteration, "mean_score": float(stats.mean_score),
                "std_score": float(stats.std_score), "max_score": float(stats.max_score),
                "min_score": float(stats.min_score), **{name: float(value) for name, value in losses.items()},
                "iteration_time_s": time.time() - started, "wall_time_s": self.wall_time_s()}

    def _evolve(self, stop: Callable[[], bool]) -> dict:
        """ask, score the population on the workers, gather the gradient parts, tell; raises Interrupted on a stop."""
        import ray

        started = time.time()
        lost_before, hung_before = self.pool.workers_lost, self.pool.workers_killed_hung
        seed = self.method.ask(self.state)
        theta_ref = ray.put(np.asarray(self.state.theta))  # once per iteration; each node fetches it once
        result = self.pool.score_population(theta_ref, seed, self.state.iteration, should_stop=stop)
        _check_scores(result.scores, result.valid, self.state.iteration + 1)
        scored = time.time()
        weights = self.method.weights(result.scores, result.valid)
        parts, parts_here = self.pool.gradient_parts(
            seed, weights, result.owners, functools.partial(self.method.parts.chunk_here, seed, weights),
            should_stop=stop)
        state, stats = self.method.tell(self.state, result.scores, result.valid, parts)
        state.theta.block_until_ready()
        self.state = state  # only a finished iteration moves the state: an interrupted one is dropped
        now = time.time()
        row = {"iteration": state.iteration, **_score_stats(stats), "requeued_chunks": result.requeued_chunks,
               "workers_lost": self.pool.workers_lost - lost_before,
               "workers_killed_hung": self.pool.workers_killed_hung - hung_before,
               "gradient_parts_on_driver": parts_here, "iteration_time_s": now - started,
               "update_time_s": now - scored, "wall_time_s": self.wall_time_s(),
               "gradient_norm": stats.gradient_norm, "update_norm": stats.update_norm,
               "parameter_norm": stats.parameter_norm, "workers": self.pool.live_workers,
               "worker_nodes": [node[:12] for node in result.worker_nodes], **result.traffic.metrics()}
        if result.new_worker_first_result_s:
            row["new_worker_first_result_s"] = [round(s, 3) for s in result.new_worker_first_result_s]
        return row

    def record(self, row: dict) -> None:
        """Evaluates if due (and after the last iteration), writes the row, checkpoints if due."""
        iteration, options = row["iteration"], self.options
        # Decided once per iteration, at the row's clock: the loop stops on the same verdict, so the row that
        # ends a run is always the evaluated one (a fresh look at the clock a moment later could differ).
        self.finished = self.reached_iterations() or self.out_of_time(row["wall_time_s"])
        if self.held_out is not None and (self.eval_due(iteration, row["wall_time_s"]) or self.finished):
            row.update(self.evaluate())
            self.next_eval_s = _next_multiple(row["wall_time_s"], options.eval_every_minutes)
        self.write(row)
        if options.checkpoint_every > 0 and iteration % options.checkpoint_every == 0:
            self.save()

    def eval_due(self, iteration: int, wall_time_s: float) -> bool:
        """Every ``eval_every`` iterations, and each time training time passes an ``eval_every_minutes`` mark."""
        every = self.options.eval_every
        return (every > 0 and iteration % every == 0) or wall_time_s >= self.next_eval_s

    def write(self, row: dict) -> None:
        self.log.write(row)  # the source of truth first
        self.events.write(row)

    def close(self) -> None:
        self.log.close()
        self.events.close()
        self.writer.close()
        if self.pool is not None:
            self.pool.shutdown()


def _plan_use_scorers(config: Config, env, unravel, num_episodes: int):
    """(the agent watching its shuffled plan, the agent reading it) on the held-out episodes, for PiZero with a
    planner; None otherwise. The first gives the share of its actions another episode's plan would change, the
    second the score with that plan: what the plan is worth, at every point of the learning curve."""
    if config.gradient_trained or config.planner == "none" or num_episodes < 2:
        return None
    from pizero_ray.agent import episodes

    watching = methods.acting_agent(config, env, watch="shuffled")
    ablated = methods.acting_agent(config, env, plan_ablation="shuffled")
    return (episodes.make_plan_use_scorer(watching, env, unravel, num_episodes),
            episodes.make_scorer(ablated, env, unravel, num_episodes))


def _next_multiple(seconds: float, every_minutes: float | None) -> float:
    """The first multiple of ``every_minutes`` (in seconds) after ``seconds``; infinity without one."""
    if every_minutes is None:
        return float("inf")
    every = 60.0 * every_minutes
    return (math.floor(seconds / every) + 1) * every


def _score_stats(stats) -> dict:
    return {"mean_score": stats.mean_score, "std_score": stats.std_score, "max_score": stats.max_score,
            "min_score": stats.min_score, "pairs_evaluated": stats.pairs, "non_finite_scores": stats.non_finite_scores}


def _check_scores(scores: np.ndarray, valid: np.ndarray, iteration: int) -> None:
    """Warns, one line, of members whose score is NaN or infinite (they rank last: es.shaping); raises
    TrainingError when no member's is finite: nothing is left to learn from, and the environment or the agent
    is broken."""
    broken = np.argwhere(~np.isfinite(scores) & valid[:, None])
    if broken.size == 0:
        return
    pair, member = (int(i) for i in broken[0])
    first = f"pair {pair}'s {'+' if member == 0 else '-'}sigma member scored {scores[pair, member]}"
    if len(broken) == 2 * int(valid.sum()):
        raise TrainingError(f"iteration {iteration}: no member scored a finite score ({first}); check the "
                            "environment's rewards")
    _log.warning("pizero: warning: iteration %d: %d member(s) scored NaN or infinity and rank last (%s)",
                 iteration, len(broken), first)


def train(
    run_path: Path,
    config: Config,
    options: RunOptions,
    on_iteration: Callable[[dict], None] | None = None,
    on_start: Callable[[dict], None] | None = None,
    worker_factory=None,
) -> dict:
    """Trains until ``options.iterations`` iterations are done, resuming from the newest good checkpoint.

    With ``options.minutes`` it also stops, after the iteration under way,
    once the run's training wall-clock (across resumes) reaches the budget.
    Returns {"iteration", "parameter_hash", "stopped_by", "out_of_time",
    "workers_killed", "workers_lost", "workers_killed_hung"}: ``stopped_by``
    names the signal that interrupted training (after a checkpoint was saved),
    or None; ``out_of_time`` says the wall-clock budget ended it; the workers
    SIGKILLed by a chaos run's schedule, the workers found dead (actor death,
    node loss), and those the pool killed as hung. Refuses (``writer_lock.RunDirInUse``) a
    run dir that another live process is writing. ``worker_factory`` (a
    ``workers.WorkerFactory``) replaces the rollout workers (the scale model's stubs).
    """
    with writer_lock.hold(run_path):
        return _train(run_path, config, options, on_iteration, on_start, worker_factory)


def _train(run_path: Path, config: Config, options: RunOptions, on_iteration, on_start, worker_factory) -> dict:
    from pizero_ray.trainer import ray_setup

    if config.gradient_trained:
        connection = f"{config.method} in this process (no Ray)"
    else:  # Ray first: it forks its processes before JAX starts its threads
        connection = ray_setup.init(options.address)
    compile_cache.enable(options.pool.compile_cache)
    run = _Run(run_path, config, options, worker_factory)
    if on_start:
        on_start({"connection": connection, "start_iteration": run.start_iteration, "parameters": run.layout.size,
                  "workers": options.pool.workers if run.pool else 0})
    stop = _StopRequest()
    try:
        with stop:
            run.begin()
            # A resumed run may have nothing left to do. Judged at its last row's clock, as record() judged
            # that row: a run stopped (killed) a moment short of its budget trains one more iteration, and so
            # ends on an evaluated row; the clock now would already be past the budget and end it unevaluated.
            run.finished = run.reached_iterations() or run.out_of_time(run.wall_offset)
            while not run.finished and not stop():
                try:
                    row = run.iterate(stop)
                except Interrupted:
                    break  # the unfinished iteration is dropped; the last finished one is saved below
                run.record(row)
                if on_iteration:
                    on_iteration(row)
            run.save()  # on normal exit and on SIGTERM/SIGINT alike
    finally:
        run.close()
    stopped_by = signal.Signals(stop.signal).name if stop.signal is not None else None
    return {"iteration": run.state.iteration, "parameter_hash": runs.parameter_hash(np.asarray(run.state.theta)),
            "stopped_by": stopped_by, "out_of_time": stop.signal is None and not run.reached_iterations(),
            "workers_killed": run.pool.chaos_kills if run.pool else 0,
            "workers_lost": run.pool.workers_lost if run.pool else 0,
            "workers_killed_hung": run.pool.workers_killed_hung if run.pool else 0}
