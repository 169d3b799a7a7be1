"""The config: an unchosen chunk size follows the population; a chosen bad one is a one-line error."""

import argparse
import dataclasses
import json
import re

import jax
import numpy as np
import pytest

from pizero_ray import envs
from pizero_ray.agent import make_agent
from pizero_ray.cli import commands, training
from pizero_ray.config import Config, ConfigError, build_config, largest_divisor_at_most
from pizero_ray.presets import ENV_PRESETS, METHOD_ENV_PRESETS, METHOD_PRESETS, PIZERO_ENV_PRESETS, PRESETS
from pizero_ray.settings import declared, lookup


def _parse(argv: list[str]):
    """The ``pizero`` command line's arguments, parsed as ``main`` parses them."""
    return commands.build_parser().parse_args(argv)


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
    args = _parse(["train", "--run-dir", "unused", "--env", "tsp", "--population", "24"])
    config = training.train_config(args)
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
    "root_noise": 0.0, "seed": 0, "sigma": 0.1, "episodes_per_member": 1, "weight_decay": 0.0,
}
# The method, and the gradient-trained baselines' settings: an ES run's are these defaults.
OLD_DEFAULTS.update({"method": "pizero", "selfplay_episodes": 32, "updates_per_iteration": 8, "batch_size": 128,
                     "replay_size": 256, "unroll_steps": 5, "action_grid": 16})
OLD_DEFAULTS["init_from"] = None  # --init-from (a curriculum's next stage): none by default
OLD_DEFAULTS["simulator_randomness"] = "sampled"  # AlphaZero's search redraws 2048's tiles and Pac-Man's ghosts
OLD_DEFAULTS["lr_decay_iterations"] = 0  # a constant step size unless asked
# How the rollout's loops are compiled: the same scores either way; mctx's loops by default.
OLD_DEFAULTS.update({"episode_loop": "until_done", "simulation_loop": "fori"})
OLD_DEFAULTS["chunks_per_launch"] = 1  # a worker's device call: one chunk unless asked
OLD_DEFAULTS["common_episodes"] = False  # each pair its own episodes unless asked
# The default preset's rank-1 noise (at least as good as full rank on every environment at equal time).
DEFAULT = {"perturbation_rank": 1}
# The paper's preset; its "Trials: 5" are 5 independent runs, not episodes per member.
PAPER = {"chance_outcomes": 3, "chunk_size": 40, "learning_rate": 0.001, "population": 1000}
# PiZero's measured search and decoder per environment (presets.PIZERO_ENV_PRESETS), default and gpu presets only.
READS_ONLY_THE_PLAN = {"decoder_inputs": ["action", "visits", "value", "qvalues"]}  # TSP, the default environment
BATCHED_GUMBEL = {"planner": "gumbel", "num_simulations": 4}  # Collect, Sokoban, 2048
TINY = {"chunk_size": 2, "hidden_size": 8, "latent_size": 8, "memory_size": 8, "num_abstract_actions": 2,
        "num_simulations": 2, "population": 4}


@pytest.mark.parametrize("preset, overrides, differences", [
    ("default", {}, {**DEFAULT, **READS_ONLY_THE_PLAN}),
    ("paper", {}, PAPER),
    ("tiny", {}, TINY),
    ("default", {"env": "2048"}, {**DEFAULT, **BATCHED_GUMBEL, "env": "2048", "population": 128,
                                  "episodes_per_member": 4, "env_args": {"horizon": 1000, "tile_encoding": "one_hot"}}),
    ("default", {"env": "2048", "env_args": {"horizon": 200}},
     {**DEFAULT, **BATCHED_GUMBEL, "env": "2048", "population": 128, "episodes_per_member": 4,
      "env_args": {"horizon": 200, "tile_encoding": "one_hot"}}),
    ("paper", {"env": "2048"}, {**PAPER, "env": "2048", "env_args": {"horizon": 1000}}),
    ("paper", {"env": "pacman"}, {**PAPER, "env": "pacman", "env_args": {"horizon": 1000}}),
    ("default", {"env": "pacman-po"}, {**DEFAULT, "env": "pacman-po", "population": 128, "action_selection": "sample"}),
    ("default", {"env": "sokoban"}, {**DEFAULT, **BATCHED_GUMBEL, "env": "sokoban", "population": 64,
                                     "chunk_size": 16, "episodes_per_member": 4, "env_args": {"view": "centred"}}),
    ("default", {"env": "collect"}, {**DEFAULT, **BATCHED_GUMBEL, "env": "collect", "env_args": {"view": "centred"}}),
    ("default", {"env": "collect", "method": "es"}, {**DEFAULT, "env": "collect", "method": "es", "planner": "none",
                                                     "env_args": {"view": "centred"}}),
    ("paper", {"env": "sokoban"}, {**PAPER, "env": "sokoban"}),
    ("tiny", {"env": "sokoban"}, {**TINY, "env": "sokoban"}),
    ("default", {"env": "flp-mean"}, {**DEFAULT, "env": "flp-mean", "episodes_per_member": 12, "weight_decay": 0.01,
                                      "env_args": {"view": "grid"}}),
    ("paper", {"env": "collect"}, {**PAPER, "env": "collect"}),
    # explicit values beat the environment's preset; --env-arg changes only the parameters it names
    ("paper", {"env": "2048", "env_args": {"tile_encoding": "one_hot"}},
     {**PAPER, "env": "2048", "env_args": {"horizon": 1000, "tile_encoding": "one_hot"}}),
    ("paper", {"env": "2048", "env_args": {"horizon": 50}}, {**PAPER, "env": "2048", "env_args": {"horizon": 50}}),
    ("default", {"env": "sokoban", "env_args": (("levels", "/b/train"), ("view", "absolute"))},
     {**DEFAULT, **BATCHED_GUMBEL, "env": "sokoban", "population": 64, "chunk_size": 16, "episodes_per_member": 4,
      "env_args": {"levels": "/b/train", "view": "absolute"}}),
    ("default", {"env": "sokoban", "population": 48},
     {**DEFAULT, **BATCHED_GUMBEL, "env": "sokoban", "population": 48, "chunk_size": 16, "episodes_per_member": 4,
      "env_args": {"view": "centred"}}),
    ("default", {"env": "flp", "episodes_per_member": 2},
     {**DEFAULT, "env": "flp", "episodes_per_member": 2, "weight_decay": 0.01, "env_args": {"view": "grid"}}),
    ("paper", {"env": "pacman", "population": 600, "seed": 7},
     {**PAPER, "env": "pacman", "env_args": {"horizon": 1000}, "population": 600, "seed": 7}),
])
def test_presets_build_these_configs(preset, overrides, differences):
    assert json.loads(build_config(preset, **overrides).to_json()) == {**OLD_DEFAULTS, **differences}


@pytest.mark.parametrize("preset, overrides, expected", [
    ("default", {"method": "es"}, {"planner": "none", "learning_rate": 0.01}),
    ("default", {"method": "alphazero"}, {"planner": "muzero", "learning_rate": 1e-3, "root_noise": 0.25}),
    ("paper", {"method": "muzero"}, {"chance_outcomes": 0, "num_simulations": 10, "hidden_size": 64}),
    ("default", {"method": "muzero", "planner": "gumbel", "root_noise": 1.0}, {"planner": "gumbel", "root_noise": 1.0}),
    # A method's settings for one environment (FLP's): only there, only for that method, and below explicit ones.
    ("default", {"method": "muzero", "env": "flp"}, {"action_grid": 8, "num_simulations": 10, "learning_rate": 1e-3}),
    ("paper", {"method": "muzero", "env": "flp-mean"}, {"action_grid": 8, "hidden_size": 64}),
    ("default", {"method": "muzero", "env": "flp", "action_grid": 16}, {"action_grid": 16}),
    ("default", {"method": "alphazero", "env": "flp-mean"}, {"action_grid": 16, "num_simulations": 32}),
    ("default", {"method": "alphazero", "env": "flp", "num_simulations": 10}, {"num_simulations": 10}),
    ("default", {"method": "alphazero", "env": "tsp"}, {"num_simulations": 32}),
    ("default", {"method": "muzero", "env": "tsp"}, {"action_grid": 16}),
    ("default", {"method": "pizero", "env": "flp"},
     {"num_simulations": 10, "weight_decay": 0.01, "env_args": (("view", "grid"),)}),
    ("default", {"method": "es", "env": "flp-mean"}, {"weight_decay": 0.01}),
    # the baselines keep the flat client coordinates and no decay, as measured; an explicit value still wins
    ("default", {"method": "alphazero", "env": "flp"}, {"weight_decay": 0.0, "env_args": (("view", "flat"),)}),
    ("default", {"method": "muzero", "env": "flp-mean"}, {"weight_decay": 0.0}),
    ("default", {"method": "muzero", "env": "flp", "weight_decay": 0.001}, {"weight_decay": 0.001}),
    ("default", {"method": "muzero", "env": "flp-mean", "env_args": {"view": "grid"}},
     {"env_args": (("view", "grid"),)}),
    ("default", {"method": "muzero", "env": "pacman-po"}, {"replay_size": 1024, "batch_size": 128}),
    ("default", {"method": "muzero", "env": "collect", "replay_size": 512}, {"replay_size": 512}),
    ("default", {"method": "alphazero", "env": "collect"}, {"num_simulations": 10, "replay_size": 256}),
    ("default", {"method": "muzero", "env": "sokoban"}, {"replay_size": 256}),
    # 2048: the ES agents play the scored 1,000 moves with one-hot tiles, the baselines the games they were measured on
    ("default", {"method": "es", "env": "2048"}, {"env_args": (("horizon", 1000), ("tile_encoding", "one_hot"))}),
    ("default", {"method": "alphazero", "env": "2048"}, {"env_args": (("horizon", 200), ("tile_encoding", "log2"))}),
    ("default", {"method": "muzero", "env": "2048", "env_args": {"horizon": 1000}},
     {"env_args": (("horizon", 1000), ("tile_encoding", "log2"))}),
])
def test_each_method_and_method_environment_pair_has_its_preset(preset, overrides, expected):
    config = build_config(preset, **overrides)
    assert {name: getattr(config, name) for name in expected} == expected


@pytest.mark.parametrize("overrides, message", [
    ({"method": "sarsa"}, "unknown method 'sarsa' (choose from pizero, es, alphazero, muzero)"),
    ({"method": "es", "planner": "muzero"}, "planner must be none, got 'muzero'"),
    ({"method": "alphazero", "planner": "none"}, "method alphazero searches with planner muzero (PUCT) or gumbel"),
    ({"method": "muzero", "chance_outcomes": 3}, "method muzero has no chance nodes: chance_outcomes must be 0, got 3"),
    ({"method": "alphazero", "replay_size": 16}, "replay_size 16 is below selfplay_episodes 32"),
    ({"method": "muzero", "unroll_steps": 0}, "unroll_steps must be a positive integer, got 0"),
    ({"lr_decay_iterations": -1}, "lr_decay_iterations must be a non-negative integer, got -1"),
    ({"method": "alphazero", "lr_decay_iterations": 100},
     "lr_decay_iterations is for ES methods, got 100 with method 'alphazero'"),
])
def test_a_bad_method_setting_is_one_line_naming_it(overrides, message):
    with pytest.raises(ConfigError, match=re.escape(message)):
        build_config("default", **overrides)


@pytest.mark.parametrize("preset", ["default", "paper", "tiny"])
def test_an_environment_of_your_own_gets_the_global_preset_alone(preset):
    """An import path has no presets of its own (nor a method's for it): the global preset's values, and no
    KeyError. Its parameters are its own: no registered environment's env_args reach it."""
    own = build_config(preset, env="examples.corridor:make", method="alphazero")
    registered = build_config(preset, env="tsp", method="alphazero")  # tsp has no env preset; alphazero on tsp has
    assert dataclasses.replace(own, env="tsp") == dataclasses.replace(registered, num_simulations=own.num_simulations)
    assert own.num_simulations == {**PRESETS[preset], **METHOD_PRESETS["alphazero"]}.get("num_simulations", 10)
    assert own.env_args == ()


@pytest.mark.parametrize("env, message", [
    ("chess", "unknown env 'chess' (choose from 2048, collect"),
    ("examples.corridor:", "environment 'examples.corridor:': an import path must read module:factory"),
    ("examples corridor:make", "an import path must read module:factory"),
])
def test_an_env_is_a_registered_name_or_an_import_path(env, message):
    with pytest.raises(ConfigError, match=re.escape(message)):
        build_config("tiny", env=env)
    assert build_config("tiny", env="any.module:factory").env == "any.module:factory"  # not imported until built


def test_environment_presets_name_real_environments_and_presets():
    assert set(ENV_PRESETS) <= set(envs.ENV_NAMES)
    assert all(set(by_preset) <= set(PRESETS) for by_preset in ENV_PRESETS.values())
    assert not hasattr(envs, "training_preset")
    assert {env for _, env in METHOD_ENV_PRESETS} <= set(envs.ENV_NAMES)
    assert {method for method, _ in METHOD_ENV_PRESETS} <= set(METHOD_PRESETS)
    assert set(PIZERO_ENV_PRESETS) <= set(envs.ENV_NAMES)
    fields = {field.name for field in dataclasses.fields(Config)}
    assert all(set(values) <= fields for values in PIZERO_ENV_PRESETS.values())


def test_pizero_searches_as_measured_per_environment_in_the_default_and_gpu_presets_only():
    collect = {preset: build_config(preset, env="collect") for preset in PRESETS}
    for preset in ("default", "gpu"):
        assert (collect[preset].planner, collect[preset].num_simulations) == ("gumbel", 4)
        assert build_config(preset, env="tsp").decoder_inputs == ("action", "visits", "value", "qvalues")
    assert (collect["paper"].planner, collect["paper"].num_simulations) == ("muzero", 10)
    assert (collect["tiny"].planner, collect["tiny"].num_simulations) == ("muzero", 2)
    assert build_config("default", env="flp").planner == "muzero"  # no measurement moved it
    for method in ("es", "alphazero", "muzero"):  # the other methods keep their own search
        config = build_config("default", env="collect", method=method)
        assert (config.planner == "gumbel", config.num_simulations) == (False, 10)
    # Without a planner the measured search is not used: --planner none is the same agent as --method es
    unplanned, es = build_config("default", env="collect", planner="none"), build_config("default", env="collect",
                                                                                           method="es")
    spec = envs.make("collect", **dict(es.env_args)).spec
    first, second = (make_agent(config, spec).init(jax.random.PRNGKey(0)) for config in (unplanned, es))
    assert jax.tree.structure(first) == jax.tree.structure(second)
    assert all(np.array_equal(a, b) for a, b in zip(jax.tree.leaves(first), jax.tree.leaves(second)))
    assert unplanned.effective_decoder_inputs == es.effective_decoder_inputs == ("state",)


def test_the_gpu_preset_keeps_each_environments_default_at_a_device_sized_population():
    for env in envs.ENV_NAMES:
        config = build_config("gpu", env=env)  # validates
        default = build_config("default", env=env)
        assert (config.population, config.chunk_size, config.chunks_per_launch, config.perturbation_rank) == (
            16384, 256, 32, 1)
        assert config.env_args == default.env_args  # the views and horizons of the default
        assert config.episodes_per_member == default.episodes_per_member
    assert dict(build_config("gpu", env="sokoban").env_args)["view"] == "centred"
    assert build_config("gpu", env="tsp", population=64, chunk_size=16, chunks_per_launch=4).population == 64


# --------------------------------------------------------------------------- settings declared once


def test_train_help_names_each_method_environment_setting_from_its_table():
    (sub,) = [a for a in commands.build_parser()._actions if isinstance(a, argparse._SubParsersAction)]
    train = {a.dest: a.help for a in sub.choices["train"]._actions}
    assert train["num_simulations"] == ("search budget K (alphazero on tsp, flp, flp-mean: 32; "
                                        "pizero on collect, sokoban, 2048: 4) (default 10)")
    assert "(pizero on tsp: action,visits,value,qvalues)" in train["decoder_inputs"]
    assert train["replay_size"].endswith("(muzero on collect, pacman, pacman-po: 1024) (default 256)")
    assert train["action_grid"].endswith("(muzero on flp, flp-mean: 8) (default 16)")
    assert train["batch_size"].endswith("positions per Adam step (default 128)")  # no table entry, no note


def test_train_help_shows_the_default_presets_values_and_says_whose_they_are():
    (sub,) = [a for a in commands.build_parser()._actions if isinstance(a, argparse._SubParsersAction)]
    train = sub.choices["train"]
    helps = {a.dest: a.help for a in train._actions}
    default = build_config("default")
    assert helps["perturbation_rank"].endswith(f"(default {default.perturbation_rank})")  # the preset's, not 0
    assert helps["learning_rate"].endswith(f"(default {default.learning_rate:g})")
    assert helps["run_dir"] and "--preset default's on --env tsp" in train.description


def test_every_option_of_train_is_a_declared_setting_or_the_commands_own():
    from pizero_ray.trainer.options import PoolOptions, RunOptions

    (sub,) = [a for a in commands.build_parser()._actions if isinstance(a, argparse._SubParsersAction)]
    train = {a.dest: a for a in sub.choices["train"]._actions}
    settings = [s for cls in (Config, RunOptions) for s in declared(cls) if s.flag]
    assert {s.name for s in settings} | {"help", "run_dir", "preset", "no_progress", "verbose"} == set(train)
    for s in settings:
        assert train[s.name].option_strings == [s.flag] and train[s.name].default is None  # presets apply
    run_fields = {f.name for f in dataclasses.fields(RunOptions)}
    assert not run_fields & {f.name for f in dataclasses.fields(PoolOptions)}  # RunOptions.create tells them apart


@pytest.mark.parametrize("argv, expected", [
    (["--lr", "0.5"], {"learning_rate": 0.5}),
    (["--lr-decay-iterations", "14000"], {"lr_decay_iterations": 14000}),
    (["--simulations", "3", "--abstract-actions", "3"], {"num_simulations": 3, "num_abstract_actions": 3}),
    (["--hidden", "5", "--latent", "6", "--memory", "7"], {"hidden_size": 5, "latent_size": 6, "memory_size": 7}),
    (["--decoder-inputs", "state, visits"], {"decoder_inputs": ("state", "visits")}),
    (["--env-arg", "num_cities=8", "--env-arg", "mask_placed=false"],
     {"env_args": (("mask_placed", False), ("num_cities", 8))}),
    (["--preset", "paper", "--env", "pacman"], {"env": "pacman", "population": 1000, "env_args": (("horizon", 1000),)}),
])
def test_config_flags_set_their_fields(argv, expected):
    config = training.train_config(_parse(["train", "--run-dir", "unused", *argv]))
    assert {name: getattr(config, name) for name in expected} == expected


def test_run_options_come_from_their_declared_defaults_and_flags():
    from pizero_ray.trainer.options import PoolOptions, RunOptions

    args = _parse(["train", "--run-dir", "unused"])
    assert training.run_options(args, 400) == RunOptions(iterations=400)
    assert RunOptions(iterations=1).pool.chunk_timeout_s == 300.0 == lookup(PoolOptions, "chunk_timeout_s").default
    args = _parse(["resume", "unused", "--iterations", "9", "--workers", "3", "--max-workers", "5",
                   "--no-pin-cores", "--chunk-timeout", "10", "--compile-cache", "none"])
    options = training.run_options(args, args.iterations)
    assert options.iterations == 9 and options.pool.target_workers == 5 and not options.pool.pin_cores
    assert (options.pool.workers, options.pool.chunk_timeout_s, options.pool.compile_cache) == (3, 10.0, "none")
    args = _parse(["resume", "unused", "--minutes", "5", "--eval-every-minutes", "0.5",
                   "--eval-env-arg", "levels=valid", "--eval-env-arg", "horizon=60"])
    options = training.run_options(args, None)
    assert options.eval_every_minutes == 0.5 and options.eval_env_args == (("horizon", 60), ("levels", "valid"))


def test_a_resume_keeps_the_stored_learning_curve_schedule_unless_an_option_is_given(tmp_path):
    from pizero_ray.storage import run_dir

    args = _parse(["train", "--run-dir", "unused", "--eval-every", "25", "--eval-episodes", "64",
                   "--eval-env-arg", "levels=valid"])
    trained = training.run_options(args, 100)
    run_dir.write_schedule(tmp_path, trained.schedule())
    kept = run_dir.read_schedule(tmp_path)
    assert kept == {"eval_every": 25, "eval_every_minutes": None, "eval_episodes": 64,
                    "eval_env_args": [["levels", "valid"]], "checkpoint_every": 25, "keep_checkpoints": 3}
    resumed = training.run_options(_parse(["resume", "unused", "--minutes", "30"]), None, kept)
    assert [getattr(resumed, name) for name in kept] == [getattr(trained, name) for name in kept]
    args = _parse(["resume", "unused", "--minutes", "30", "--eval-every", "0"])
    assert training.run_options(args, None, kept).eval_every == 0  # a given option wins
    assert run_dir.read_schedule(tmp_path / "older") == {}  # run dirs from before: today's defaults


@pytest.mark.parametrize("values, message", [
    ({"min_fraction": 0.0}, "--min-fraction must be in (0, 1], got 0.0"),
    ({"min_fraction": 1.5}, "--min-fraction must be in (0, 1], got 1.5"),
    ({"chunk_timeout_s": 0.0}, "--chunk-timeout must be positive, got 0.0"),
    ({"workers": 3, "max_workers": 2}, "--max-workers 2 is below --workers 3"),
    ({"workers": 0}, "--workers must be at least 1, got 0"),
    ({"eval_every": -1}, "--eval-every must be at least 0, got -1"),
    ({"eval_every_minutes": 0.0}, "--eval-every-minutes must be positive, got 0.0"),
    ({"gradient_on": "gpu"}, "--gradient-on must be one of auto, workers, driver, got 'gpu'"),
])
def test_run_options_validate_themselves(values, message):
    from pizero_ray.trainer.options import RunOptions

    with pytest.raises(ConfigError) as error:
        RunOptions.create(iterations=1, **values)
    assert str(error.value) == message


@pytest.mark.parametrize("gradient_on, rank, gpus, on_driver", [
    ("auto", 0, 0.0, False), ("auto", 1, 0.0, True), ("auto", 1, 1.0, False),  # a GPU's noise: GPU workers
    ("workers", 1, 0.0, False), ("driver", 0, 0.0, True), ("driver", 0, 1.0, True),
])
def test_where_the_gradient_parts_are_formed(gradient_on, rank, gpus, on_driver):
    from pizero_ray.trainer.options import PoolOptions

    assert PoolOptions(gradient_on=gradient_on, gpus_per_worker=gpus).gradient_on_driver(rank) is on_driver


def test_a_run_dir_written_before_the_rename_still_reads():
    from pizero_ray.config import Config

    old = json.loads(build_config("default", env="flp").to_json())
    old["trials"] = old.pop("episodes_per_member")
    assert Config.from_dict(old).episodes_per_member == 12
    assert build_config("paper").episodes_per_member == 1  # the paper's "Trials: 5" are five runs, not episodes


def test_an_alphazero_run_written_before_sampled_futures_goes_on_foreseeing_them():
    from pizero_ray.config import Config

    new = json.loads(build_config("default", method="alphazero", env="2048").to_json())
    assert Config.from_dict(new).simulator_randomness == "sampled"
    del new["simulator_randomness"]
    assert Config.from_dict(new).simulator_randomness == "foreseen"


def test_env_args_merge_key_by_key_across_every_preset_layer(monkeypatch):
    monkeypatch.setitem(METHOD_ENV_PRESETS, ("alphazero", "sokoban"), {"env_args": {"num_boxes": 2}})
    config = build_config("default", method="alphazero", env="sokoban", env_args={"horizon": 30})
    assert dict(config.env_args) == {"view": "centred", "num_boxes": 2, "horizon": 30}
