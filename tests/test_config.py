"""The config: an unchosen chunk size follows the population; a chosen bad one is a one-line error."""

import pytest

from pizero_ray.cli import commands as cli
from pizero_ray.config import ConfigError, build_config, largest_divisor_at_most


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
