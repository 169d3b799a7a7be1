"""The one typed, frozen configuration, validated once at the edge.

Everything that changes what training computes lives here (and is saved to
RUN_DIR/config.json); how it is run (workers, cluster address, run dir) does
not, so the same config gives the same parameters on any cluster.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import dataclass
from typing import Any

from pizero_ray.presets import PRESETS, env_preset

PLANNERS = ("muzero", "gumbel", "none")
DECODERS = ("pointer", "flat")
DECODER_INPUTS = ("state", "action", "visits", "value")
FITNESS_SHAPINGS = ("centered_ranks", "none")
ACTION_SELECTIONS = ("argmax", "sample")


class ConfigError(ValueError):
    """A bad setting; the message is one line naming the value."""


@dataclass(frozen=True)
class Config:
    # environment
    env: str = "tsp"
    env_args: tuple[tuple[str, Any], ...] = ()
    # agent (paper: one hidden layer of 64, abstract state 64, k = 4)
    hidden_size: int = 64
    latent_size: int = 64
    memory_size: int = 64
    num_abstract_actions: int = 4
    planner: str = "muzero"
    num_simulations: int = 10
    chance_outcomes: int = 0  # > 0: chance nodes (Stochastic MuZero search) with this many abstract outcomes
    pb_c_init: float = 1.25
    pb_c_base: float = 19652.0
    abstract_discount: float = 1.0
    root_noise: float = 0.0  # Dirichlet fraction (muzero) or Gumbel scale (gumbel)
    decoder: str = "pointer"
    decoder_inputs: tuple[str, ...] = DECODER_INPUTS
    action_selection: str = "argmax"
    action_noise: float = 1.0  # Gumbel scale when action_selection == "sample"
    # evolution strategies
    population: int = 256  # antithetic pairs per iteration (2x members)
    trials: int = 1  # episodes per member, averaged
    sigma: float = 0.1
    perturbation_rank: int = 0  # 0: full-rank noise; r > 0: rank-r noise per weight matrix (EGGROLL; opt-in)
    learning_rate: float = 0.01
    weight_decay: float = 0.0
    fitness_shaping: str = "centered_ranks"
    chunk_size: int = 32  # pairs per unit of work; fixed so results never depend on workers
    seed: int = 0

    def validate(self) -> "Config":
        from envs import ENV_NAMES  # local: keeps config importable without JAX set up

        def need(condition: bool, message: str) -> None:
            if not condition:
                raise ConfigError(message)

        need(self.env in ENV_NAMES, f"unknown env {self.env!r} (choose from {', '.join(ENV_NAMES)})")
        for name in ("hidden_size", "latent_size", "memory_size", "num_abstract_actions",
                     "population", "trials", "chunk_size"):
            value = getattr(self, name)
            need(isinstance(value, int) and value > 0, f"{name} must be a positive integer, got {value!r}")
        need(self.planner in PLANNERS, f"unknown planner {self.planner!r} (choose from {', '.join(PLANNERS)})")
        need(self.planner == "none" or self.num_simulations > 0,
             f"num_simulations must be positive with planner {self.planner!r}, got {self.num_simulations}")
        need(self.num_abstract_actions >= 2 or self.planner == "none",
             f"num_abstract_actions must be at least 2 to plan, got {self.num_abstract_actions}")
        need(isinstance(self.chance_outcomes, int) and self.chance_outcomes >= 0,
             f"chance_outcomes must be a non-negative integer, got {self.chance_outcomes!r}")
        need(self.chance_outcomes == 0 or self.planner in ("muzero", "none"),
             f"chance nodes need the muzero planner (mctx has no stochastic Gumbel search), got {self.planner!r}")
        need(self.chance_outcomes != 1, "chance_outcomes must be 0 (none) or at least 2, got 1")
        need(self.decoder in DECODERS, f"unknown decoder {self.decoder!r} (choose from {', '.join(DECODERS)})")
        need(len(self.decoder_inputs) > 0, "decoder_inputs must name at least one of " + ", ".join(DECODER_INPUTS))
        for item in self.decoder_inputs:
            need(item in DECODER_INPUTS, f"unknown decoder input {item!r} (choose from {', '.join(DECODER_INPUTS)})")
        need(self.action_selection in ACTION_SELECTIONS,
             f"unknown action selection {self.action_selection!r} (choose from {', '.join(ACTION_SELECTIONS)})")
        need(self.fitness_shaping in FITNESS_SHAPINGS,
             f"unknown fitness shaping {self.fitness_shaping!r} (choose from {', '.join(FITNESS_SHAPINGS)})")
        need(isinstance(self.perturbation_rank, int) and self.perturbation_rank >= 0,
             f"perturbation_rank must be a non-negative integer, got {self.perturbation_rank!r}")
        need(self.sigma > 0, f"sigma must be positive, got {self.sigma}")
        need(self.learning_rate > 0, f"learning_rate must be positive, got {self.learning_rate}")
        need(self.weight_decay >= 0, f"weight_decay must be non-negative, got {self.weight_decay}")
        need(0 <= self.root_noise <= 1 or (self.planner == "gumbel" and self.root_noise >= 0),
             f"root_noise must be in [0, 1] (any non-negative Gumbel scale), got {self.root_noise}")
        need(0 < self.abstract_discount <= 1, f"abstract_discount must be in (0, 1], got {self.abstract_discount}")
        need(self.population % self.chunk_size == 0,
             f"population {self.population} is not a multiple of chunk_size {self.chunk_size}")
        need(0 <= self.seed < 2**32, f"seed must be in [0, 2^32), got {self.seed}")
        return self

    @property
    def effective_decoder_inputs(self) -> tuple[str, ...]:
        """Without a planner there is no search result: the decoder sees the state only."""
        return ("state",) if self.planner == "none" else self.decoder_inputs

    @property
    def num_chunks(self) -> int:
        return self.population // self.chunk_size

    def env_kwargs(self) -> dict[str, Any]:
        return dict(self.env_args)

    def to_json(self) -> str:
        data = dataclasses.asdict(self)
        data["env_args"] = dict(self.env_args)
        return json.dumps(data, indent=2, sort_keys=True)

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> "Config":
        known = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ConfigError(f"unknown config keys: {', '.join(unknown)}")
        data = dict(data)
        if "env_args" in data:
            data["env_args"] = tuple(sorted(dict(data["env_args"]).items()))
        if "decoder_inputs" in data:
            data["decoder_inputs"] = tuple(data["decoder_inputs"])
        return cls(**data)

    @classmethod
    def from_json(cls, text: str) -> "Config":
        return cls.from_dict(json.loads(text))


def largest_divisor_at_most(number: int, limit: int) -> int:
    """The largest divisor of ``number`` that is at most ``limit`` (1 if ``limit`` < 1)."""
    return max((d for d in range(1, min(number, limit) + 1) if number % d == 0), default=1)


def build_config(preset: str = "default", **overrides: Any) -> Config:
    """Global preset, then the environment's own overrides for it, then explicit overrides (pizero_ray.presets).

    Without an explicit ``chunk_size`` the chunk is the largest divisor of the
    population not above the preset's chunk size (32 by default).
    """
    if preset not in PRESETS:
        raise ConfigError(f"unknown preset {preset!r} (choose from {', '.join(PRESETS)})")
    explicit = {k: v for k, v in overrides.items() if v is not None}
    values = {**PRESETS[preset], **env_preset(explicit.get("env", Config.env), preset), **explicit}
    population = values.get("population", Config.population)
    if "chunk_size" not in explicit and isinstance(population, int) and population > 0:
        # An unchosen chunk size follows the population (24 pairs: one chunk of 24, not an error);
        # still a pure function of the config, so the results stay independent of the workers.
        values["chunk_size"] = largest_divisor_at_most(population, values.get("chunk_size", Config.chunk_size))
    if isinstance(values.get("env_args"), dict):
        values["env_args"] = tuple(sorted(values["env_args"].items()))
    return Config(**values).validate()
