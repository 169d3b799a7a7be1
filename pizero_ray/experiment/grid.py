"""An experiment's grid: environments x methods x seeds, one budget, and where each trial's run dir lives.

Pure dataclasses (no Ray, no JAX): the command line builds an ``Experiment``,
checks every trial's configuration before anything starts, and writes it to
``OUT/experiment.json`` so that a restore can tell it is the same experiment.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from pizero_ray.config import METHODS, Config, ConfigError, build_config

SPEC_FILE = "experiment.json"
RUNS = "runs"


@dataclass(frozen=True)
class Trial:
    env: str
    method: str
    seed: int

    @property
    def name(self) -> str:
        return f"{self.env}/{self.method}/seed{self.seed}"


@dataclass(frozen=True)
class Experiment:
    """Every trial trains ``budget_minutes`` of wall-clock (``--minutes``) with ``cpus_per_trial`` CPUs.

    ``overrides``: Config fields given for every trial (a smaller population,
    say). ``env_args`` / ``eval_env_args``: per environment, its parameters
    for training and for the learning curve's evaluations (Sokoban: train on
    one level set, evaluate on another).
    """

    envs: tuple[str, ...]
    methods: tuple[str, ...]
    seeds: int
    budget_minutes: float
    eval_every_minutes: float
    eval_episodes: int = 256
    cpus_per_trial: int = 2
    preset: str = "default"
    overrides: tuple[tuple[str, Any], ...] = ()
    env_args: tuple[tuple[str, tuple[tuple[str, Any], ...]], ...] = ()
    eval_env_args: tuple[tuple[str, tuple[tuple[str, Any], ...]], ...] = ()

    def __post_init__(self) -> None:
        from pizero_ray import envs as environments
        for env in self.envs:  # a registered name, or an environment of your own by import path module:factory
            if env not in environments.ENV_NAMES and not environments.is_import_path(env):
                known = ", ".join(environments.ENV_NAMES)
                raise ConfigError(f"--envs: unknown environment {env!r}; choose from {known}, or name your own by "
                                  "import path module:factory")
        for method in self.methods:
            if method not in METHODS:
                raise ConfigError(f"--methods: unknown method {method!r}; choose from {', '.join(METHODS)}")
        for flag, items in (("--envs", self.envs), ("--methods", self.methods)):
            if not items or len(set(items)) != len(items):
                raise ConfigError(f"{flag} must name at least one, each once, got {','.join(items)!r}")
        for flag, value in (("--seeds", self.seeds), ("--budget-minutes", self.budget_minutes),
                            ("--eval-every-minutes", self.eval_every_minutes),
                            ("--eval-episodes", self.eval_episodes), ("--cpus-per-trial", self.cpus_per_trial)):
            if not value > 0:
                raise ConfigError(f"{flag} must be positive, got {value}")
        for flag, per_env in (("--env-arg", self.env_args), ("--eval-env-arg", self.eval_env_args)):
            for env, _ in per_env:
                if env not in self.envs:
                    raise ConfigError(f"{flag}: environment {env!r} is not in --envs {','.join(self.envs)}")

    @property
    def trials(self) -> list[Trial]:
        """Seed-major: every (env, method) gets seed 0 before any gets seed 1. An experiment cut short still
        covers the whole grid, and later seeds find their programs in the compile cache."""
        return [Trial(env, method, seed) for seed in range(self.seeds) for env in self.envs
                for method in self.methods]

    def config(self, trial: Trial) -> Config:
        """The trial's configuration: the preset, the overrides, its env's parameters, its method and seed."""
        env_args = dict(dict(self.env_args).get(trial.env, ()))
        return build_config(self.preset, **dict(self.overrides), env=trial.env, method=trial.method,
                            seed=trial.seed, **({"env_args": env_args} if env_args else {}))

    def run_options(self, trial: Trial, compile_cache: str | None = None) -> dict:
        """The trial's RunOptions fields: the budget, evaluations on the clock, CPUs for ES workers."""
        options = {"minutes": self.budget_minutes, "eval_every_minutes": self.eval_every_minutes,
                   "eval_episodes": self.eval_episodes, "workers": self.cpus_per_trial,
                   "eval_env_args": tuple(sorted(dict(dict(self.eval_env_args).get(trial.env, ())).items()))}
        if compile_cache is not None:
            options["compile_cache"] = compile_cache
        return options

    def final_evaluation(self, evaluated: list[dict]) -> dict | None:
        """A trial's last evaluated metrics row (``run_dir.evaluated_rows``) once it has spent the budget;
        None before (not started, or not done)."""
        if not evaluated or evaluated[-1]["wall_time_s"] < 60.0 * self.budget_minutes:
            return None
        return evaluated[-1]

    def to_json(self) -> dict:
        return dataclasses.asdict(self)

    @classmethod
    def from_json(cls, data: dict) -> "Experiment":
        def pairs(items):
            return tuple((key, tuple(map(tuple, value)) if isinstance(value, list) else value) for key, value in items)

        return cls(**{**data, "envs": tuple(data["envs"]), "methods": tuple(data["methods"]),
                      "overrides": tuple(map(tuple, data["overrides"])),
                      "env_args": pairs(data["env_args"]), "eval_env_args": pairs(data["eval_env_args"])})


def run_path(out: Path, trial: Trial) -> Path:
    return out / RUNS / trial.env / trial.method / f"seed{trial.seed}"


def check(experiment: Experiment) -> None:
    """Builds every trial's configuration and environment: a bad one is a one-line ConfigError before any trial.

    The seed changes neither, so each (env, method) is built once (Sokoban reads its level files each time).
    """
    from pizero_ray import envs as environments
    for trial in [trial for trial in experiment.trials if trial.seed == 0]:
        config = experiment.config(trial)
        for env_args in ({}, dict(dict(experiment.eval_env_args).get(trial.env, ()))):
            try:
                environments.make(config.env, **{**config.env_kwargs(), **env_args})
            except ValueError as error:
                raise ConfigError(f"{trial.name}: {error}") from None


PER_ENV_FIELDS = ("envs", "env_args", "eval_env_args")  # what may differ between sittings of one experiment


def combine(sittings: list[Experiment]) -> Experiment:
    """Sittings of one experiment, each over other environments, as one grid (for its report).

    They must agree on everything else (methods, seeds, budget, evaluations,
    CPUs, preset, overrides): else a one-line ConfigError naming the field.
    """
    first = sittings[0]
    seen: dict[str, int] = {}
    for index, sitting in enumerate(sittings):
        changed = [f.name for f in dataclasses.fields(Experiment)
                   if f.name not in PER_ENV_FIELDS and getattr(sitting, f.name) != getattr(first, f.name)]
        if changed:
            name = changed[0]
            raise ConfigError(f"sitting {index + 1} differs from sitting 1 in {name}: "
                              f"{getattr(sitting, name)!r} against {getattr(first, name)!r}")
        for env in sitting.envs:
            if env in seen:
                raise ConfigError(f"environment {env!r} is in sittings {seen[env] + 1} and {index + 1}")
            seen[env] = index
    return dataclasses.replace(first, envs=tuple(seen),
                               env_args=tuple(item for sitting in sittings for item in sitting.env_args),
                               eval_env_args=tuple(item for sitting in sittings for item in sitting.eval_env_args))


def write_spec(out: Path, experiment: Experiment) -> None:
    """OUT/experiment.json; an existing one must describe the same experiment (else a one-line error)."""
    path = out / SPEC_FILE
    if path.exists():
        existing = Experiment.from_json(json.loads(path.read_text()))
        if existing != experiment:
            changed = [f.name for f in dataclasses.fields(Experiment)
                       if getattr(existing, f.name) != getattr(experiment, f.name)]
            raise ConfigError(f"{out} holds a different experiment (it differs in {', '.join(changed)}); "
                              f"give another --out, or the same options to resume it")
        return
    out.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(SPEC_FILE + ".tmp")
    tmp.write_text(json.dumps(experiment.to_json(), indent=1) + "\n")
    tmp.replace(path)


def read_spec(out: Path) -> Experiment:
    path = out / SPEC_FILE
    if not path.is_file():
        raise ConfigError(f"{out} holds no experiment ({SPEC_FILE} is missing)")
    return Experiment.from_json(json.loads(path.read_text()))
