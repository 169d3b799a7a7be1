"""Training presets: config overrides by name, global and per environment.

``build_config(preset, env=..., method=...)`` applies ``PRESETS[preset]``,
then ``ENV_PRESETS[env][preset]`` (if any), then ``METHOD_PRESETS[method]``,
then ``method_env_preset(method, env, preset)``: ``METHOD_ENV_PRESETS[(method,
env)]`` for the baselines, ``PIZERO_ENV_PRESETS[env]`` for PiZero in the
``default`` and ``gpu`` presets (if any), then explicit overrides. The
environments know nothing of these: the dependency runs config -> presets
only. An explicit ``--env-arg`` changes only the parameter it names: the
preset's other ``env_args`` stay (``--env-arg view=absolute`` undoes a
preset's view).
"""

from __future__ import annotations

from typing import Any

# "gpu" sizes a worker's device call. On an H200 one batched agent step (10 simulations) took about 15 ms at
# population 64 (docs/performance.md, "On a GPU"): launches and loop conditions, not arithmetic, so a step
# should cost about the same for many more members (not yet measured). 1M agent-steps/s at 15 ms a step
# needs 15,000 members a step: a launch of 32 chunks of 256 pairs is 16,384 members. Chunks stay 256 pairs
# (the gradient's unit and order of summation); two launches an iteration, so that two workers sharing a GPU
# each have one. Run it as
#   pizero train --preset gpu --workers 1 --gpus-per-worker 1
# Sized from that one measurement, not yet measured itself (make device-run measures it on a GPU).
_GPU_SIZED: dict[str, Any] = {"population": 16384, "chunk_size": 256, "chunks_per_launch": 32}

# "default" is what learns best on a 2-core machine (see docs/tsp.md); "paper" is the paper's table. Its
# "Trials: 5" are five independent runs (the plots' mean and band), so "paper" plays one episode per member.
# "default" perturbs each weight matrix with rank-1 noise: at equal wall-clock (3 minutes, 3 seeds) it learns
# at least as well as full-rank noise on all eight environments, better on Collect and both FLPs, in 1.5 to
# 3.5 times the iterations (docs/performance.md). "paper" keeps full-rank noise, as OpenAI-ES has it.
PRESETS: dict[str, dict[str, Any]] = {
    "default": {"perturbation_rank": 1},
    "paper": dict(
        learning_rate=1e-3, sigma=0.1, population=1000, hidden_size=64,
        latent_size=64, memory_size=64, num_abstract_actions=4, num_simulations=10, chance_outcomes=3,
        chunk_size=40,
    ),
    # A GPU worker's population: see _GPU_SIZED below. Each environment's "default" overrides apply too.
    "gpu": {"perturbation_rank": 1, **_GPU_SIZED},
    # For tests and smoke runs: compiles in seconds.
    "tiny": dict(
        hidden_size=8, latent_size=8, memory_size=8, num_abstract_actions=2,
        num_simulations=2, population=4, chunk_size=2,
    ),
}

# Horizon 20 makes a Collect episode twice as long as TSP10's: the global
# defaults stay CPU-friendly without change (0.09 s per chunk of 32 pairs on a
# 2-core CPU, against TSP10's 0.04 s). "default" observes the agent-centred
# window: 8 minutes without a planner reach -5.30 on 1,000 held-out episodes
# against -7.95 with the absolute planes, although an iteration costs 2.4x as
# much (docs/collect.md).
_COLLECT: dict[str, dict[str, Any]] = {"default": {"env_args": {"view": "centred"}}, "paper": {}}

# FLP episodes are num_facilities (3) steps long, a third of TSP10's, so
# several episodes per member cost little and smooth out how much the
# instance alone moves a member's fitness (three cost about what one TSP
# episode does: 0.05 s against 0.04 s per chunk of 32 pairs on a 2-core CPU).
# Both objectives (flp, flp-mean). "default" observes the clients as a grid of cells (their share, and
# the share of the cost they pay): in 30 minutes without a planner
# -0.468 against -0.480 on flp and -0.2345 against -0.241 on flp-mean with the flat coordinates (one seed
# each, the intervals apart; docs/flp.md). Weight decay 0.01 holds the parameter norm near 55 instead of
# growing to 400-490, and ES without a planner scores -0.455 and -0.453 against -0.461 and -0.471 on flp,
# -0.2354 and -0.2367 against -0.2379 and -0.2378 on flp-mean in 30 minutes (seeds 0 and 1; docs/flp.md).
# Twelve instances per member instead of three (an iteration 1.8x as long, not 4x: a 3-step episode is
# cheap next to an iteration's fixed cost) then score -0.446 and -0.446 on flp, -0.2350 and -0.2318 on
# flp-mean (seeds 0 and 1; docs/flp.md): ahead on three of the four, level on the fourth.
# The baselines keep the flat coordinates and no decay (METHOD_ENV_PRESETS).
_FLP: dict[str, dict[str, Any]] = {
    "default": {"episodes_per_member": 12, "weight_decay": 0.01, "env_args": {"view": "grid"}},
    "paper": {},
}

# 2048: "default" trains on the scored game (horizon 1,000, where a greedy game lasts 259 moves) with one-hot
# tiles and four games per member: without a planner, 30 minutes on the whole machine (2 workers) reach 5,076
# and 5,069 (two seeds) against 4,633 and 4,736 with two games on a host as fast; on one core two games beat
# one (4,728 against 4,459), one-hot tiles beat log2 (4,459 against 3,985) and training at horizon 1,000 beats
# 500 (3,825) (docs/2048.md). Its games are hundreds of moves, so it halves the population (an iteration on
# the whole machine: about 1.8 s on the faster host, 4.9 s on the slower). "paper" plays 1000-move games with
# the log2 tiles.
_GAME2048: dict[str, dict[str, Any]] = {
    "default": {"population": 128, "episodes_per_member": 4, "env_args": {"horizon": 1000, "tile_encoding": "one_hot"}},
    "paper": {"env_args": {"horizon": 1000}},
}

# Pac-Man, both variants (pacman, pacman-po): "default" halves the population
# (episodes are 128 steps: about 2 s an iteration in one process on a 2-core
# machine; TSP10's default: 0.4 s) and samples its actions: the ghosts are
# nearly deterministic, so with argmax actions the whole population soon plays
# one game (eat 20 pellets, get caught: 200), every member ties and ES gets no
# signal; sampled, 30 minutes without a planner reach 1,882 and 2,050 on
# pacman (two seeds; docs/pacman.md). "paper" plays Jumanji's full 1000-step game.
_PACMAN: dict[str, dict[str, Any]] = {
    "default": {"population": 128, "action_selection": "sample"},
    "paper": {"env_args": {"horizon": 1000}},
}

# Sokoban episodes are five times longer than TSP10's (H = 50), so the CPU
# default evaluates a quarter of the population per iteration; in "paper" the
# paper's table applies as is (H = 50 is the environment's default). "default"
# observes the player-centred 9x9 window: 8 minutes without a planner on
# unfiltered train cover 0.295 goals on unfiltered valid against 0.117 with the
# absolute planes (random: 0.309; docs/sokoban.md). Four levels per member
# instead of one: 30 minutes on one core cover 0.383 and 0.343 goals against
# 0.324 and 0.311 (seeds 0 and 1; each pair's intervals overlap, the direction
# agrees), with a third of the iterations.
_SOKOBAN: dict[str, dict[str, Any]] = {
    "default": {"population": 64, "chunk_size": 16, "episodes_per_member": 4, "env_args": {"view": "centred"}},
    "paper": {},
}

# Environment name (as envs.ENV_NAMES spells it) -> preset -> overrides on top of PRESETS[preset].
ENV_PRESETS: dict[str, dict[str, dict[str, Any]]] = {
    "collect": _COLLECT,
    "flp": _FLP,
    "flp-mean": _FLP,
    "2048": _GAME2048,
    "pacman": _PACMAN,
    "pacman-po": _PACMAN,
    "sokoban": _SOKOBAN,
}


# Method -> overrides on top of the global and environment presets. es is PiZero without a planner. The
# gradient-trained baselines take Adam's usual step size and AlphaZero's root noise (Dirichlet fraction 0.25).
METHOD_PRESETS: dict[str, dict[str, Any]] = {
    "es": {"planner": "none"},
    "alphazero": {"learning_rate": 1e-3, "root_noise": 0.25, "chance_outcomes": 0},
    "muzero": {"learning_rate": 1e-3, "root_noise": 0.25, "chance_outcomes": 0},
}


# (method, env) -> overrides on top of the method's: a baseline's settings for one environment, where its
# screens and a 30-minute run chose other than the method's defaults (docs/baselines.md).
# AlphaZero on FLP: 32 simulations instead of 10, so the search visits more than a few of the 256 grid
# actions: in 30 minutes -0.464 against -0.543 on flp and -0.228 against -0.395 on flp-mean.
# MuZero on FLP: an 8x8 grid of 64 actions instead of 16x16 (256): in 30 minutes -0.917 against -1.189 on flp
# and -0.498 against -0.540 on flp-mean, with an iteration 5x cheaper. (One seed each; 1,000 held-out
# instances, the intervals apart in all four.)
# MuZero on Collect and both Pac-Mans: 1,024 episodes of replay instead of 256. In 30 minutes -1.376 against
# -2.380 on Collect, 1,576 against 1,170 on Pac-Man, 1,640 against 1,606 on pacman-po (one seed each, the
# intervals apart), and ahead at equal iterations on all three for most of the run.
# AlphaZero on TSP: 32 simulations; in 30 minutes a tour of 2.979 against 3.047 (the intervals apart).
# Both baselines on FLP observe the flat client coordinates and take no weight decay, as they were measured;
# the grid view and the decay of the ES agents' default are not measured for them.
_FLP_AS_MEASURED = {"weight_decay": 0.0, "env_args": {"view": "flat"}}
# Both baselines on 2048 self-play the 200-move games with log2 tiles they were measured with (the ES agents'
# default is 1,000 moves with one-hot tiles).
_SHORT_LOG2_GAMES = {"env_args": {"horizon": 200, "tile_encoding": "log2"}}
METHOD_ENV_PRESETS: dict[tuple[str, str], dict[str, Any]] = {
    ("alphazero", "tsp"): {"num_simulations": 32},
    ("alphazero", "flp"): {"num_simulations": 32, **_FLP_AS_MEASURED},
    ("alphazero", "flp-mean"): {"num_simulations": 32, **_FLP_AS_MEASURED},
    ("muzero", "flp"): {"action_grid": 8, **_FLP_AS_MEASURED},
    ("muzero", "flp-mean"): {"action_grid": 8, **_FLP_AS_MEASURED},
    ("alphazero", "2048"): _SHORT_LOG2_GAMES,
    ("muzero", "2048"): _SHORT_LOG2_GAMES,
    ("muzero", "collect"): {"replay_size": 1024},
    ("muzero", "pacman"): {"replay_size": 1024},
    ("muzero", "pacman-po"): {"replay_size": 1024},
}


# PiZero's search and decoder per environment: the configuration that scored best at equal time over 3 seeds,
# each against the configuration it replaced (MuZero's search, 10 simulations, the decoder reading the abstract
# state beside the plan) trained the same 10 minutes on one core with the same seed, paired on 1,000 held-out
# episodes (2048: 200 games; docs/planning.md, "How each default was chosen"). Only in the "default" and "gpu" presets:
# "paper" keeps the paper's table, "tiny" its small search. Without a planner (--method es, --planner none)
# these settings are not used.
# Gumbel search with one simulation per abstract action (4) is a one-step lookahead that PiZero computes in one
# batched call of its model (planner.every_action_once): 4.6 to 11.6 times the iterations of MuZero's with 10.
# Collect: +2.43, +1.62, +1.89 coins; Sokoban: +0.220, +0.124, +0.132 goals; 2048: +1,673, +1,395, +1,743 points.
# TSP: the decoder reads only the plan (the abstract action, visit counts, value and the root children's
# Q-values), not the abstract state: tours shorter by 0.012, 0.017 and 0.010 (the first interval touches zero).
_GUMBEL_4 = {"planner": "gumbel", "num_simulations": 4}
PIZERO_ENV_PRESETS: dict[str, dict[str, Any]] = {
    "collect": _GUMBEL_4,
    "sokoban": _GUMBEL_4,
    "2048": _GUMBEL_4,
    "tsp": {"decoder_inputs": ("action", "visits", "value", "qvalues")},
}
PIZERO_PRESETS = ("default", "gpu")  # the presets PIZERO_ENV_PRESETS applies in


def method_env_preset(method: str, env: str, preset: str) -> dict[str, Any]:
    """The method's overrides for the environment in ``preset``: a baseline's ``METHOD_ENV_PRESETS`` entry in
    every preset, PiZero's ``PIZERO_ENV_PRESETS`` entry in the presets it is measured for."""
    if method == "pizero":
        return dict(PIZERO_ENV_PRESETS.get(env, {})) if preset in PIZERO_PRESETS else {}
    return dict(METHOD_ENV_PRESETS.get((method, env), {}))


def method_env_notes(name: str) -> list[str]:
    """Where ``METHOD_ENV_PRESETS`` or ``PIZERO_ENV_PRESETS`` set the setting ``name``, as "method on env, env:
    value" (for --help)."""
    def text(value: Any) -> str:  # env_args are a dict (key=value), a list setting a tuple (as its flag takes it)
        if isinstance(value, dict):
            return ", ".join(f"{k}={v}" for k, v in value.items())
        return ",".join(map(str, value)) if isinstance(value, tuple) else str(value)

    groups: dict[tuple[str, str], list[str]] = {}
    tables = [*METHOD_ENV_PRESETS.items(), *((("pizero", env), values) for env, values in PIZERO_ENV_PRESETS.items())]
    for (method, env), values in tables:
        if name in values:
            groups.setdefault((method, text(values[name])), []).append(env)
    return [f"{method} on {', '.join(envs)}: {value}" for (method, value), envs in groups.items()]


def env_preset(env: str, preset: str) -> dict[str, Any]:
    """The environment's overrides for a preset; empty where it has none, as for every environment of your own
    (an import path, ``--env mypackage.mymodule:make``): the global preset alone applies to those."""
    if env not in ENV_PRESETS:
        return {}
    if preset == "gpu":  # the environment's default (views, episodes per member), at the GPU's population
        return {name: value for name, value in ENV_PRESETS[env]["default"].items() if name not in _GPU_SIZED}
    return dict(ENV_PRESETS[env].get(preset, {}))


def preset_values(preset: str, env: str, method: str) -> dict[str, Any]:
    """What ``preset`` sets for ``method`` on ``env``, layer over layer as ``config.build_config`` applies them
    (without the chunk size that follows the population): the defaults ``pizero train --help`` shows."""
    layers = (PRESETS[preset], env_preset(env, preset), METHOD_PRESETS.get(method, {}),
              method_env_preset(method, env, preset))
    return {name: value for layer in layers for name, value in layer.items()}
