"""Running an experiment on Ray Tune: one trial per (env, method, seed), restorable after any interruption.

Each trial trains its run dir (OUT/runs/ENV/METHOD/seedN) with the driver,
under the experiment's wall-clock budget (``--minutes``: training time,
evaluations excluded, carried across resumes). The run dir is the trial's
state: a trial that Tune starts again after an interruption resumes it from
its newest checkpoint, and a trial whose run has spent its budget only
reports. Tune's ``time_total_s`` stop is a ceiling on top, for a trial that
hangs: ``CEILING_FACTOR`` budgets plus ``CEILING_SLACK_S``.

Resources: every trial gets ``cpus_per_trial`` CPUs. A PiZero/ES trial's
driver takes none (an empty head bundle) and starts that many one-CPU
worker actors inside the trial's placement group (Tune captures child
actors); AlphaZero and MuZero learn inside the trial's own process, which
holds the CPUs and pins itself to as many cores (as ES workers do).
"""

from __future__ import annotations

import json
import os
import time
from pathlib import Path

from ray.tune.experiment import Trial as TuneTrial
from ray.tune.schedulers import FIFOScheduler

from pizero_ray.experiment import grid

TUNE_DIR = "tune"
CEILING_FACTOR = 3.0
CEILING_SLACK_S = 600.0


class GridOrder(FIFOScheduler):
    """First come, first served in the grid's own order (seed-major), also after a restore.

    A restored experiment reloads its trials in no particular order, and Tune's
    FIFO takes the first pending one it lists: a grid restored and cut short
    again would leave holes in its first seeds. Pickled with the tuner, so a
    restore keeps it.
    """

    def __init__(self, trial_names: list[str]):
        super().__init__()
        self._rank = {name: rank for rank, name in enumerate(trial_names)}

    def _key(self, trial) -> int:
        spec = trial.config["trial"]
        return self._rank.get(grid.Trial(spec["env"], spec["method"], spec["seed"]).name, len(self._rank))

    def choose_trial_to_run(self, tune_controller):
        trials = tune_controller.get_trials()
        for status in (TuneTrial.PENDING, TuneTrial.PAUSED):
            waiting = [trial for trial in trials if trial.status == status]
            if waiting:
                return min(waiting, key=self._key)
        return None


def _trial_resources(cpus: int):
    """tune.with_resources' callable: the placement group a trial (given its config) needs."""
    from ray import tune

    from pizero_ray.config import GRADIENT_METHODS

    def resources(config: dict):
        if config["trial"]["method"] in GRADIENT_METHODS:
            return tune.PlacementGroupFactory([{"CPU": cpus}])
        return tune.PlacementGroupFactory([{}] + [{"CPU": 1}] * cpus)

    return resources


def train_trial(config: dict) -> None:
    """The Tune trainable: trains (or resumes) one trial's run dir, reporting every evaluation."""
    from ray import tune

    from pizero_ray.storage import run_dir as rundir
    from pizero_ray.trainer import chunk_scoring, driver
    from pizero_ray.trainer.options import RunOptions

    trial_config = config["trial"]
    os.chdir(trial_config["cwd"])  # Tune starts a trial in its own directory: relative paths (levels=...) are ours
    out = Path(trial_config["out"])
    experiment = grid.read_spec(out)
    trial = grid.Trial(trial_config["env"], trial_config["method"], trial_config["seed"])
    path = grid.run_path(out, trial)
    config = experiment.config(trial)
    options = RunOptions.create(**experiment.run_options(trial, trial_config.get("compile_cache")))
    if not (path / rundir.CONFIG_FILE).exists():
        rundir.write_config(path, config)
        rundir.write_schedule(path, options.schedule())  # a later pizero resume keeps it

    def report(row: dict) -> None:
        if "eval_mean_score" in row:
            tune.report({"iteration": row["iteration"], "training_minutes": row["wall_time_s"] / 60.0,
                         "eval_mean_score": row["eval_mean_score"]})

    # A baseline learns in this process: pinned to cores of its own, as an ES trial's workers pin theirs, so
    # that trials running side by side each get their CPUs and no more.
    cores = chunk_scoring.CoreClaim.claim(experiment.cpus_per_trial) if config.gradient_trained else None
    try:
        driver.train(path, config, options, on_iteration=report)
    finally:
        if cores is not None:
            cores.release()
    report(rundir.evaluated_rows(path)[-1])  # the final evaluation, also when a restored trial had nothing to train


def run(out: Path, experiment: grid.Experiment, address: str | None = None,
        compile_cache: str | None = None) -> dict:
    """Trains every trial not yet finished; returns {trial name: its last reported result}.

    A new ``out`` starts the experiment; an ``out`` that holds it (same grid)
    restores Tune's state, so finished trials stay finished and unfinished
    ones resume their run dirs.
    """
    from ray import tune

    from pizero_ray.trainer import ray_setup

    out = out.resolve()
    grid.write_spec(out, experiment)
    ray_setup.init(address)
    trainable = tune.with_resources(train_trial, _trial_resources(experiment.cpus_per_trial))
    tune_path = out / TUNE_DIR
    if tune.Tuner.can_restore(str(tune_path)):
        tuner = tune.Tuner.restore(str(tune_path), trainable, resume_unfinished=True, resume_errored=True)
    else:
        tuner = _new_tuner(out, experiment, trainable, compile_cache)
    results = tuner.fit()
    return _summary(out, experiment, results)


def _new_tuner(out: Path, experiment: grid.Experiment, trainable, compile_cache: str | None):
    from ray import tune

    trial_configs = [{"out": str(out), "cwd": os.getcwd(), "env": t.env, "method": t.method, "seed": t.seed,
                      "compile_cache": compile_cache} for t in experiment.trials]
    ceiling = CEILING_FACTOR * 60.0 * experiment.budget_minutes + CEILING_SLACK_S
    return tune.Tuner(
        trainable,
        param_space={"trial": tune.grid_search(trial_configs)},
        tune_config=tune.TuneConfig(trial_dirname_creator=lambda t: _trial_dirname(t.config["trial"]),
                                    scheduler=GridOrder([t.name for t in experiment.trials])),
        run_config=tune.RunConfig(
            name=TUNE_DIR, storage_path=str(out), stop={"time_total_s": ceiling}, verbose=0,
            failure_config=tune.FailureConfig(max_failures=2)),
    )


def _trial_dirname(trial_config: dict) -> str:
    return f"{trial_config['env']}-{trial_config['method']}-seed{trial_config['seed']}"


def _summary(out: Path, experiment: grid.Experiment, results) -> dict:
    """Each trial's final state from its run dir (the source of truth), and Tune's errors if any."""
    from pizero_ray.storage import run_dir as rundir

    # An error's last line is the exception itself; its first is Ray's "ray::ImplicitFunc.train() (pid=...)".
    errors = [_last_line(str(result.error)) for result in results if result.error is not None]
    trials = {}
    for trial in experiment.trials:
        final = experiment.final_evaluation(rundir.evaluated_rows(grid.run_path(out, trial)))
        trials[trial.name] = final and {"iteration": final["iteration"],
                                        "training_minutes": round(final["wall_time_s"] / 60.0, 3),
                                        "eval_mean_score": final["eval_mean_score"]}
    return {"out": str(out), "finished": sum(t is not None for t in trials.values()), "trials": trials,
            "errors": errors, "time": time.strftime("%Y-%m-%d %H:%M:%S")}


def _last_line(text: str) -> str:
    lines = [line for line in text.splitlines() if line.strip()]
    return lines[-1].strip() if lines else text


def write_summary(out: Path, summary: dict) -> None:
    (out / "summary.json").write_text(json.dumps(summary, indent=1) + "\n")
