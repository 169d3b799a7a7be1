"""The config: an unchosen chunk size follows the population; a chosen bad one is a one-line error."""

import json

import pytest

from pizero_ray.cli import commands as cli
from pizero_ray.config import ConfigError, build_config, largest_divisor_at_most
from pizero_ray.presets import ENV_PRESETS, PRESETS


@pytest.mark.parametrize("number, limit, expected", [(24, 32, 24), (1000, 32, 25), (64, 32, 32), (7, 32, 7),
                                                     (97, 32, 1), (1000, 40, 40), (12, 0, 1)])
def test_largest_divisor_at_most(number, limit, expected):
    assert largest_divisor_at_most(number, limit) == expected


@pytest.mark.parametrize("preset, population, chunk", [("default", 24, 24), ("default", 256, 32),
                                                       ("default", 1000, 25), ("paper", None, 40),
                                                       ("paper", 600, 40), ("paper", 90, 30), ("tiny", 6, 2)])
def test_the_chunk_size_follows_the_population_when_not_given(preset, population, chunk):
    config = build_config(preset, population=population)
    assert config.chunk_size == chunk and config.population % config.chunk_size == 0


def test_an_explicit_chunk_size_that_does_not_divide_is_still_an_error():
    with pytest.raises(ConfigError, match="population 24 is not a multiple of chunk_size 32"):
        build_config("default", population=24, chunk_size=32)


def test_train_with_population_24_and_no_chunk_size_is_accepted():
    args = cli._parser().parse_args(["train", "--run-dir", "unused", "--env", "tsp", "--population", "24"])
    config = cli._train_config(args)
    assert (config.population, config.chunk_size) == (24, 24)


# --------------------------------------------------------------------------- presets, pinned
# What build_config gave before the environments' TRAINING_PRESETS moved to pizero_ray.presets
# (computed from that code): the whole config, as the defaults plus what differs from them.

OLD_DEFAULTS = {
    "abstract_discount": 1.0, "action_noise": 1.0, "action_selection": "argmax", "chance_outcomes": 0,
    "chunk_size": 32, "decoder": "pointer", "decoder_inputs": ["state", "action", "visits", "value"], "env": "tsp",
    "env_args": {}, "fitness_shaping": "centered_ranks", "hidden_size": 64, "latent_size": 64,
    "learning_rate": 0.01, "memory_size": 64, "num_abstract_actions": 4, "num_simulations": 10,
    "pb_c_base": 19652.0, "pb_c_init": 1.25, "perturbation_rank": 0, "planner": "muzero", "population": 256,
    "root_noise": 0.0, "seed": 0, "sigma": 0.1, "trials": 1, "weight_decay": 0.0,
}
PAPER = {"chance_outcomes": 3, "chunk_size": 40, "learning_rate": 0.001, "population": 1000, "trials": 5}
TINY = {"chunk_size": 2, "hidden_size": 8, "latent_size": 8, "memory_size": 8, "num_abstract_actions": 2,
        "num_simulations": 2, "population": 4}


@pytest.mark.parametrize("preset, overrides, differences", [
    ("default", {}, {}),
    ("paper", {}, PAPER),
    ("tiny", {}, TINY),
    ("default", {"env": "2048"}, {"env": "2048", "population": 128}),
    ("paper", {"env": "2048"}, {**PAPER, "env": "2048", "env_args": {"horizon": 1000}}),
    ("paper", {"env": "pacman"}, {**PAPER, "env": "pacman", "env_args": {"horizon": 1000}}),
    ("default", {"env": "pacman-po"}, {"env": "pacman-po", "population": 128}),
    ("default", {"env": "sokoban"}, {"env": "sokoban", "population": 64, "chunk_size": 16}),
    ("paper", {"env": "sokoban"}, {**PAPER, "env": "sokoban"}),
    ("tiny", {"env": "sokoban"}, {**TINY, "env": "sokoban"}),
    ("default", {"env": "flp-mean"}, {"env": "flp-mean", "trials": 3}),
    ("paper", {"env": "collect"}, {**PAPER, "env": "collect"}),
    # explicit values beat the environment's preset; --env-arg replaces its env_args as a whole
    ("paper", {"env": "2048", "env_args": {"tile_encoding": "one_hot"}},
     {**PAPER, "env": "2048", "env_args": {"tile_encoding": "one_hot"}}),
    ("default", {"env": "sokoban", "population": 48}, {"env": "sokoban", "population": 48, "chunk_size": 16}),
    ("default", {"env": "flp", "trials": 2}, {"env": "flp", "trials": 2}),
    ("paper", {"env": "pacman", "population": 600, "seed": 7},
     {**PAPER, "env": "pacman", "env_args": {"horizon": 1000}, "population": 600, "seed": 7}),
])
def test_presets_give_the_configs_they_gave_before_they_moved(preset, overrides, differences):
    assert json.loads(build_config(preset, **overrides).to_json()) == {**OLD_DEFAULTS, **differences}


def test_environment_presets_name_real_environments_and_presets():
    import envs

    assert set(ENV_PRESETS) <= set(envs.ENV_NAMES)
    assert all(set(by_preset) <= set(PRESETS) for by_preset in ENV_PRESETS.values())
    assert not hasattr(envs, "training_preset")
