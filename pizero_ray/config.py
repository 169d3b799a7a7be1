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

from pizero_ray.presets import METHOD_PRESETS, PRESETS, env_preset, method_env_preset
from pizero_ray.settings import check_finite, lookup, setting

METHODS = ("pizero", "es", "alphazero", "muzero")
GRADIENT_METHODS = ("alphazero", "muzero")  # trained by gradients on self-play, in one process (no Ray)
PLANNERS = ("muzero", "gumbel", "none")
DECODERS = ("pointer", "flat")
# What the decoder may read: the abstract state, and the search's abstract action, visit distribution, root value
# and its root children's Q-values (which move smoothly with the parameters, where few simulations' argmax and
# visits move in jumps). The default is the first four.
DECODER_INPUTS = ("state", "action", "visits", "value", "qvalues")
DEFAULT_DECODER_INPUTS = DECODER_INPUTS[:4]
FITNESS_SHAPINGS = ("centered_ranks", "difference_ranks", "none")
ACTION_SELECTIONS = ("argmax", "sample")
SIMULATOR_RANDOMNESS = ("sampled", "foreseen")
EPISODE_LOOPS = ("until_done", "horizon")
# What the decoder may be handed instead of the search's own result at evaluation: the plan ablation, which
# tells what a trained agent's plan is worth. "shuffled": another episode's plan from the same batch (each
# episode reads the next one's: a real plan, for another state); "zeroed": an all-zero result.
PLAN_ABLATIONS = ("shuffled", "zeroed")
SIMULATION_LOOPS = ("fori", "unrolled")


# How the rollout's loops compile, never what it computes (the same scores: tests/es/test_population.py): the
# only settings a run may change between sessions.
COMPILE_ONLY_SETTINGS = ("episode_loop", "simulation_loop")


class ConfigError(ValueError):
    """A bad setting; the message is one line naming the value."""


def _env_names() -> tuple[str, ...]:
    from pizero_ray.envs import ENV_NAMES  # local: keeps config importable without JAX set up

    return ENV_NAMES


@dataclass(frozen=True)
class Config:
    """Each setting's default, flag, help and choices are declared here once (pizero_ray.settings)."""

    method: str = setting(
        "pizero", flag="--method", choices=METHODS,
        help="pizero: PiZero by ES; es: the same agent without a planner (--planner none); alphazero: MCTS over "
             "the true simulator, trained by gradients on self-play; muzero: MCTS over a learned model, likewise")
    # environment
    env: str = setting(
        "tsp", flag="--env", choices=_env_names,
        help="the environment: a registered name, or your own as module:factory (docs/your-environment.md)")
    env_args: tuple[tuple[str, Any], ...] = setting(
        (), flag="--env-arg", metavar="KEY=VALUE",
        help="an environment parameter, repeatable (e.g. num_cities=8); the value is read as JSON if it can be")
    # agent (paper: one hidden layer of 64, abstract state 64, k = 4)
    hidden_size: int = setting(64, flag="--hidden", help="hidden layer width")
    latent_size: int = setting(64, flag="--latent", help="abstract state size")
    memory_size: int = setting(64, flag="--memory", help="memory size")
    num_abstract_actions: int = setting(4, flag="--abstract-actions", help="abstract actions k")
    planner: str = setting("muzero", flag="--planner", choices=PLANNERS, help="the search over abstract actions")
    num_simulations: int = setting(10, flag="--simulations", help="search budget K")
    chance_outcomes: int = setting(
        0, flag="--chance-outcomes",
        help="abstract chance outcomes per afterstate (0: deterministic abstract model; > 0: chance nodes, "
             "Stochastic MuZero search)")
    pb_c_init: float = 1.25
    pb_c_base: float = 19652.0
    abstract_discount: float = 1.0
    root_noise: float = setting(0.0, flag="--root-noise", help="Dirichlet fraction (muzero) or Gumbel scale (gumbel)")
    decoder: str = setting("pointer", flag="--decoder", choices=DECODERS, help="the action decoder")
    decoder_inputs: tuple[str, ...] = setting(DEFAULT_DECODER_INPUTS, flag="--decoder-inputs", choices=DECODER_INPUTS,
                                              help="what the decoder sees, comma-separated")
    action_selection: str = setting("argmax", flag="--action-selection", choices=ACTION_SELECTIONS,
                                    help="how the action is chosen (sample: a Gumbel-perturbed argmax)")
    action_noise: float = setting(1.0, flag="--action-noise", help="Gumbel scale when action selection is sample")
    # How the rollout's loops are compiled: the same scores either way (tests/es/test_population.py), a
    # different count of while loops a step. On a GPU each trip of a data-dependent while loop copies its
    # condition to the host before the next launch (docs/performance.md).
    episode_loop: str = setting(
        "until_done", flag="--episode-loop", choices=EPISODE_LOOPS,
        help="until_done: stop once every episode of a batch has ended (a data-dependent loop); horizon: always "
             "play to the horizon (a loop of known length); the same scores")
    simulation_loop: str = setting(
        "fori", flag="--simulation-loop", choices=SIMULATION_LOOPS,
        help="fori: mctx's loop over the simulations; unrolled: the simulations one after another in the program "
             "(no loop; a longer compile); the same scores")
    # evolution strategies
    population: int = setting(256, flag="--population", help="antithetic pairs per iteration (2x members)")
    # Episodes each member plays per iteration, its score their mean. Not the paper's "Trials: 5": those are
    # independent training runs (seeds), which the experiments repeat.
    episodes_per_member: int = setting(1, flag="--episodes-per-member", help="episodes per member, averaged")
    sigma: float = setting(0.1, flag="--sigma", help="noise scale")
    perturbation_rank: int = setting(
        0, flag="--perturbation-rank",
        help="0: full-rank noise; r > 0: rank-r noise per weight matrix, faster (EGGROLL; the default preset: 1)")
    learning_rate: float = setting(0.01, flag="--lr", help="Adam step size")
    weight_decay: float = setting(0.0, flag="--weight-decay", help="L2 weight decay")
    # ES only. Over iterations, not wall-clock, so that a run's parameters stay a function of its config and
    # iteration count alone (bit-identical on any cluster); set it to the iterations a budget buys.
    lr_decay_iterations: int = setting(
        0, flag="--lr-decay-iterations",
        help="ES: cosine decay of --lr to 0 over this many iterations, then 0 (0: a constant step size)")
    fitness_shaping: str = setting(
        "centered_ranks", flag="--fitness-shaping", choices=FITNESS_SHAPINGS,
        help="how scores become weights: centered_ranks of all 2N scores; difference_ranks: each pair's "
             "f(+) - f(-), ranked by size with its sign (blind to how hard the pair's episodes were, and to scale); "
             "none: the raw scores")
    # Common random numbers across the population: every pair plays the same episodes (new ones each
    # iteration), so a pair's difference is the perturbation's effect on those episodes, not on easier ones.
    # Off by default: no comparison has it ahead of the default yet (TSP, flp, flp-mean, and Collect's 30-minute
    # runs; docs/learning.md has each environment's figures).
    common_episodes: bool = setting(
        False, flag="--common-episodes",
        help="every pair of an iteration plays the same episodes (default: each pair its own)")
    chunk_size: int = setting(32, flag="--chunk-size",
                              help="pairs per unit of work (divides the population); fixed so results never "
                                   "depend on the workers")
    # A launch's members are what should fill a GPU (a step there is bound by launches, not arithmetic).
    # Fixed by the config, not by how chunks are handed out, because a bigger launch may round differently
    # (XLA picks its kernels by shape: on 2 CPU cores, 8 chunks of 32 pairs of the bench agent launched
    # together scored other bits than each alone), and the parameters must not depend on the workers.
    chunks_per_launch: int = setting(
        1, flag="--chunks-per-launch",
        help="chunks a worker plays in one device call, grouped by index (chunks 0..L-1, L..2L-1, ...): a GPU "
             "worker's batch; part of what is computed, so it changes the scores' last bits")
    seed: int = setting(0, flag="--seed", help="the run's seed")
    # A curriculum's next stage starts where another run stands. The parameters only: Adam starts afresh at
    # iteration 0, and the iterations' noise still comes from seed.
    init_from: str | None = setting(
        None, flag="--init-from", metavar="RUN_DIR",
        help="start from another run dir's newest parameters (the same agent shapes; a fresh optimiser state): "
             "a curriculum's next stage")
    # gradient-trained baselines (alphazero, muzero); they share the agent's sizes, --simulations, --planner
    # (muzero: PUCT, or gumbel), --root-noise, --lr and --weight-decay
    selfplay_episodes: int = setting(32, flag="--selfplay-episodes",
                                     help="alphazero/muzero: self-play episodes per iteration")
    updates_per_iteration: int = setting(8, flag="--updates-per-iteration",
                                         help="alphazero/muzero: Adam steps per iteration")
    batch_size: int = setting(128, flag="--batch-size", help="alphazero/muzero: positions per Adam step")
    replay_size: int = setting(256, flag="--replay-size", help="alphazero/muzero: episodes the replay buffer holds")
    unroll_steps: int = setting(5, flag="--unroll-steps", help="muzero: model steps unrolled in the planning loss")
    action_grid: int = setting(16, flag="--action-grid",
                               help="alphazero/muzero on continuous actions (flp): grid points per action dimension")
    simulator_randomness: str = setting(
        "sampled", flag="--simulator-randomness", choices=SIMULATOR_RANDOMNESS,
        help="alphazero on 2048 and Pac-Man: each search redraws the simulator's future tiles and ghost moves "
             "(sampled), or sees the ones the game will draw (foreseen: perfect foresight)")

    def validate(self) -> "Config":
        def need(condition: bool, message: str) -> None:
            if not condition:
                raise ConfigError(message)

        def need_choice(name: str) -> None:
            """One of the setting's declared choices, else an error naming the value and the choices."""
            value, allowed = getattr(self, name), lookup(Config, name).allowed
            need(value in allowed, f"unknown {name.replace('_', ' ')} {value!r} (choose from {', '.join(allowed)})")

        need_choice("method")
        check_finite(self, ConfigError)  # --lr inf or --sigma nan would pass every range check below
        self._validate_env()
        for name in ("hidden_size", "latent_size", "memory_size", "num_abstract_actions",
                     "population", "episodes_per_member", "chunk_size", "chunks_per_launch"):
            value = getattr(self, name)
            need(isinstance(value, int) and value > 0, f"{name} must be a positive integer, got {value!r}")
        need_choice("planner")
        need(self.planner == "none" or self.num_simulations > 0,
             f"num_simulations must be positive with planner {self.planner!r}, got {self.num_simulations}")
        need(self.num_abstract_actions >= 2 or self.planner == "none",
             f"num_abstract_actions must be at least 2 to plan, got {self.num_abstract_actions}")
        need(isinstance(self.chance_outcomes, int) and self.chance_outcomes >= 0,
             f"chance_outcomes must be a non-negative integer, got {self.chance_outcomes!r}")
        need(self.chance_outcomes == 0 or self.planner in ("muzero", "none"),
             f"chance nodes need the muzero planner (mctx has no stochastic Gumbel search), got {self.planner!r}")
        need(self.chance_outcomes != 1, "chance_outcomes must be 0 (none) or at least 2, got 1")
        need_choice("decoder")
        need(len(self.decoder_inputs) > 0, "decoder_inputs must name at least one of " + ", ".join(DECODER_INPUTS))
        for item in self.decoder_inputs:
            need(item in DECODER_INPUTS, f"unknown decoder input {item!r} (choose from {', '.join(DECODER_INPUTS)})")
        need_choice("action_selection")
        need_choice("episode_loop")
        need_choice("simulation_loop")
        need_choice("simulator_randomness")
        need_choice("fitness_shaping")
        need(isinstance(self.perturbation_rank, int) and self.perturbation_rank >= 0,
             f"perturbation_rank must be a non-negative integer, got {self.perturbation_rank!r}")
        need(self.sigma > 0, f"sigma must be positive, got {self.sigma}")
        need(self.learning_rate > 0, f"learning_rate must be positive, got {self.learning_rate}")
        need(self.weight_decay >= 0, f"weight_decay must be non-negative, got {self.weight_decay}")
        need(isinstance(self.lr_decay_iterations, int) and self.lr_decay_iterations >= 0,
             f"lr_decay_iterations must be a non-negative integer, got {self.lr_decay_iterations!r}")
        need(self.lr_decay_iterations == 0 or self.method not in GRADIENT_METHODS,
             f"lr_decay_iterations is for ES methods, got {self.lr_decay_iterations} with method {self.method!r}")
        need(0 <= self.root_noise <= 1 or (self.planner == "gumbel" and self.root_noise >= 0),
             f"root_noise must be in [0, 1] (any non-negative Gumbel scale), got {self.root_noise}")
        need(0 < self.abstract_discount <= 1, f"abstract_discount must be in (0, 1], got {self.abstract_discount}")
        need(self.population % self.chunk_size == 0,
             f"population {self.population} is not a multiple of chunk_size {self.chunk_size}")
        need(self.population % (self.chunk_size * self.chunks_per_launch) == 0,
             f"population {self.population} is not a multiple of chunk_size {self.chunk_size} x chunks_per_launch "
             f"{self.chunks_per_launch}")
        need(0 <= self.seed < 2**32, f"seed must be in [0, 2^32), got {self.seed}")
        self._validate_method()
        return self

    def _validate_env(self) -> None:
        """A registered name, or an import path module:factory (its module is imported when the env is built)."""
        from pizero_ray import envs
        from pizero_ray.envs import import_path

        if envs.is_import_path(self.env):
            try:
                import_path.parse(self.env)
            except ValueError as error:
                raise ConfigError(str(error)) from None
        elif self.env not in envs.ENV_NAMES:
            raise ConfigError(f"unknown env {self.env!r} (choose from {', '.join(envs.ENV_NAMES)}, "
                              "or name your own by import path module:factory)")

    def _validate_method(self) -> None:
        if self.method == "es" and self.planner != "none":
            raise ConfigError(f"method es is PiZero without a planner: planner must be none, got {self.planner!r}")
        if self.method not in GRADIENT_METHODS:
            return
        if self.planner not in ("muzero", "gumbel"):
            raise ConfigError(f"method {self.method} searches with planner muzero (PUCT) or gumbel, "
                              f"got {self.planner!r}")
        if self.chance_outcomes != 0:
            raise ConfigError(f"method {self.method} has no chance nodes: chance_outcomes must be 0, "
                              f"got {self.chance_outcomes}")
        for name in ("selfplay_episodes", "updates_per_iteration", "batch_size", "replay_size", "unroll_steps",
                     "action_grid"):
            value = getattr(self, name)
            if not (isinstance(value, int) and value > 0):
                raise ConfigError(f"{name} must be a positive integer, got {value!r}")
        if self.replay_size < self.selfplay_episodes:
            raise ConfigError(f"replay_size {self.replay_size} is below selfplay_episodes {self.selfplay_episodes}: "
                              "an iteration's episodes would not fit")

    @property
    def gradient_trained(self) -> bool:
        """AlphaZero or MuZero: trained by gradients on self-play in one process, not by ES on Ray."""
        return self.method in GRADIENT_METHODS

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
        known = {f.name for f in dataclasses.fields(cls)} | {"trials"}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ConfigError(f"unknown config keys: {', '.join(unknown)}")
        data = dict(data)
        if "trials" in data and "episodes_per_member" not in data:  # run dirs written before the rename
            data["episodes_per_member"] = data.pop("trials")
        # Run dirs written before the setting: their AlphaZero searched the game's own future, and a resumed or
        # evaluated run goes on doing so.
        data.setdefault("simulator_randomness", "foreseen")
        if "env_args" in data:
            data["env_args"] = tuple(sorted(dict(data["env_args"]).items()))
        if "decoder_inputs" in data:
            data["decoder_inputs"] = tuple(data["decoder_inputs"])
        return cls(**data)

    @classmethod
    def from_json(cls, text: str) -> "Config":
        return cls.from_dict(json.loads(text))


def differing_settings(a: Config, b: Config, ignore: tuple[str, ...] = COMPILE_ONLY_SETTINGS) -> list[str]:
    """The names of the settings in which ``a`` and ``b`` differ, in field order, but those in ``ignore``."""
    return [f.name for f in dataclasses.fields(Config)
            if f.name not in ignore and getattr(a, f.name) != getattr(b, f.name)]


def largest_divisor_at_most(number: int, limit: int) -> int:
    """The largest divisor of ``number`` that is at most ``limit`` (1 if ``limit`` < 1)."""
    return max((d for d in range(1, min(number, limit) + 1) if number % d == 0), default=1)


def build_config(preset: str = "default", **overrides: Any) -> Config:
    """Global preset, the environment's overrides for it, the method's, the method's for the environment, then
    explicit ones (pizero_ray.presets).

    ``env_args`` merge key by key: each layer, and the explicit ones last, change
    only the environment parameters they name; the others stay.

    Without an explicit ``chunk_size`` the chunk is the largest divisor of the
    population not above the preset's chunk size (32 by default).
    """
    if preset not in PRESETS:
        raise ConfigError(f"unknown preset {preset!r} (choose from {', '.join(PRESETS)})")
    explicit = {k: v for k, v in overrides.items() if v is not None}
    method, env = explicit.get("method", Config.method), explicit.get("env", Config.env)
    layers = (PRESETS[preset], env_preset(env, preset), METHOD_PRESETS.get(method, {}),
              method_env_preset(method, env, preset), explicit)
    values = {name: value for layer in layers for name, value in layer.items()}
    # env_args merge key by key, layer over layer: --env-arg (or a later layer) changes only the keys it names
    env_args = {key: value for layer in layers for key, value in dict(layer.get("env_args", ())).items()}
    if env_args:
        values["env_args"] = env_args
    population = values.get("population", Config.population)
    if "chunk_size" not in explicit and isinstance(population, int) and population > 0:
        # An unchosen chunk size follows the population (24 pairs: one chunk of 24, not an error);
        # still a pure function of the config, so the results stay independent of the workers.
        values["chunk_size"] = largest_divisor_at_most(population, values.get("chunk_size", Config.chunk_size))
    if isinstance(values.get("env_args"), dict):
        values["env_args"] = tuple(sorted(values["env_args"].items()))
    return Config(**values).validate()
