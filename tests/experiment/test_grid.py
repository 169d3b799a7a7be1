"""The experiment's grid: its trials, each trial's configuration and options, its spec file, bad input."""

import json

import pytest

from pizero_ray.cli import main
from pizero_ray.config import ConfigError
from pizero_ray.experiment import grid


def _experiment(**changes):
    values = dict(envs=("tsp", "sokoban"), methods=("pizero", "alphazero"), seeds=2, budget_minutes=5.0,
                  eval_every_minutes=1.0, preset="tiny", overrides=(("population", 8),),
                  env_args=(("sokoban", (("levels", "A"),)),), eval_env_args=(("sokoban", (("levels", "B"),)),))
    return grid.Experiment(**{**values, **changes})


def test_every_env_method_seed_is_a_trial_with_its_own_run_dir(tmp_path):
    experiment = _experiment()
    trials = experiment.trials
    assert len(trials) == 8 and len({t.name for t in trials}) == 8
    assert grid.run_path(tmp_path, grid.Trial("tsp", "alphazero", 1)) == tmp_path / "runs/tsp/alphazero/seed1"


def test_a_trials_config_has_its_env_method_seed_and_the_shared_overrides():
    experiment = _experiment()
    config = experiment.config(grid.Trial("sokoban", "alphazero", 1))
    assert (config.env, config.method, config.seed, config.population) == ("sokoban", "alphazero", 1, 8)
    assert dict(config.env_args) == {"levels": "A"}
    assert experiment.config(grid.Trial("tsp", "pizero", 0)).env_args == ()
    options = experiment.run_options(grid.Trial("sokoban", "pizero", 0))
    assert options["minutes"] == 5.0 and options["eval_every_minutes"] == 1.0 and options["workers"] == 2
    assert options["eval_env_args"] == (("levels", "B"),)


@pytest.mark.parametrize("changes, message", [
    ({"envs": ("tsp", "chess")}, "--envs: unknown environment 'chess'"),
    ({"methods": ("pizero", "dqn")}, "--methods: unknown method 'dqn'"),
    ({"methods": ("es", "es")}, "--methods must name at least one, each once, got 'es,es'"),
    ({"seeds": 0}, "--seeds must be positive, got 0"),
    ({"budget_minutes": -1.0}, "--budget-minutes must be positive, got -1.0"),
    ({"env_args": (("collect", (("size", 4),)),)}, "--env-arg: environment 'collect' is not in --envs tsp,sokoban"),
])
def test_bad_grids_are_one_line_errors(changes, message):
    with pytest.raises(ConfigError, match="^" + message.replace("(", r"\(").replace(")", r"\)")):
        _experiment(**changes)


def test_the_spec_round_trips_and_a_different_experiment_in_the_same_dir_is_refused(tmp_path):
    experiment = _experiment()
    grid.write_spec(tmp_path, experiment)
    assert grid.read_spec(tmp_path) == experiment
    grid.write_spec(tmp_path, experiment)  # the same experiment again: a resume
    with pytest.raises(ConfigError, match="holds a different experiment \\(it differs in seeds, budget_minutes\\)"):
        grid.write_spec(tmp_path, _experiment(seeds=3, budget_minutes=6.0))
    assert json.loads((tmp_path / grid.SPEC_FILE).read_text())["seeds"] == 2


def test_a_trial_has_a_final_evaluation_only_once_its_budget_is_spent(tmp_path):
    from pizero_ray.storage import run_dir

    experiment, trial = _experiment(), grid.Trial("tsp", "pizero", 0)
    path = grid.run_path(tmp_path, trial)
    assert experiment.final_evaluation(run_dir.evaluated_rows(path)) is None  # not started
    path.mkdir(parents=True)
    rows = [{"iteration": 0, "wall_time_s": 0.0, "eval_mean_score": -4.0},
            {"iteration": 1, "wall_time_s": 150.0, "eval_mean_score": -3.5},
            {"iteration": 2, "wall_time_s": 299.0, "mean_score": -3.4}]
    run_dir.rewrite_metrics(path, rows)
    assert experiment.final_evaluation(run_dir.evaluated_rows(path)) is None  # 5 minutes not yet trained and evaluated
    run_dir.rewrite_metrics(path, rows + [{"iteration": 3, "wall_time_s": 300.5, "eval_mean_score": -3.2}])
    assert experiment.final_evaluation(run_dir.evaluated_rows(path))["iteration"] == 3


def test_sittings_over_other_environments_combine_into_one_grid():
    first = _experiment()
    second = _experiment(envs=("collect", "flp"), env_args=(("flp", (("num_facilities", 2),)),), eval_env_args=())
    combined = grid.combine([first, second])
    assert combined.envs == ("tsp", "sokoban", "collect", "flp")
    assert combined.seeds == 2 and combined.methods == first.methods
    assert dict(combined.env_args) == {"sokoban": (("levels", "A"),), "flp": (("num_facilities", 2),)}
    assert dict(combined.eval_env_args) == {"sokoban": (("levels", "B"),)}
    assert grid.combine([first]) == first


@pytest.mark.parametrize("changes, message", [
    ({"envs": ("collect",), "env_args": (), "eval_env_args": (), "budget_minutes": 3.0},
     "sitting 2 differs from sitting 1 in budget_minutes: 3.0 against 5.0"),
    ({"envs": ("collect", "tsp"), "env_args": (), "eval_env_args": ()}, "environment 'tsp' is in sittings 1 and 2"),
])
def test_sittings_of_different_experiments_are_refused(changes, message):
    with pytest.raises(ConfigError, match="^" + message + "$"):
        grid.combine([_experiment(), _experiment(**changes)])


def test_the_command_checks_every_trial_before_anything_starts(tmp_path, capsys):
    out = tmp_path / "exp"
    code = main(["experiment", "--envs", "tsp,collect", "--methods", "es", "--seeds", "1", "--budget-minutes",
                 "1", "--out", str(out), "--env-arg", "collect:num_coins=0"])
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("pizero: error: collect/es/seed0: collect: num_coins must be")
    assert len(err.strip().splitlines()) == 1 and not out.exists()
    code = main(["experiment", "--envs", "tsp", "--budget-minutes", "0", "--out", str(out)])
    assert code == 2 and "--budget-minutes must be positive, got 0" in capsys.readouterr().err
    with pytest.raises(SystemExit):
        main(["experiment", "--envs", "tsp", "--budget-minutes", "1", "--out", str(out), "--env-arg", "levels=X"])
    assert "expected ENV:KEY=VALUE, got 'levels=X'" in capsys.readouterr().err


def test_tune_takes_pending_trials_in_the_grids_order_whatever_order_it_lists_them():
    from types import SimpleNamespace

    from ray.tune.experiment import Trial as TuneTrial

    from pizero_ray.experiment.runner import GridOrder

    experiment = _experiment()
    order = GridOrder([t.name for t in experiment.trials])

    def listed(status, trial):
        return SimpleNamespace(status=status, config={"trial": {"env": trial.env, "method": trial.method,
                                                                "seed": trial.seed}}, name=trial.name)

    trials = experiment.trials  # seed-major: tsp/pizero/seed0 first
    shuffled = [listed(TuneTrial.PENDING, t) for t in reversed(trials[1:])] + [listed(TuneTrial.TERMINATED, trials[0])]
    controller = SimpleNamespace(get_trials=lambda: shuffled)
    assert order.choose_trial_to_run(controller).name == trials[1].name  # the first unfinished, not the first listed
    for trial in shuffled:
        trial.status = TuneTrial.TERMINATED if trial.status == TuneTrial.PENDING else trial.status
    shuffled[0].status = TuneTrial.PAUSED
    assert order.choose_trial_to_run(controller).name == trials[-1].name
    shuffled[0].status = TuneTrial.TERMINATED
    assert order.choose_trial_to_run(controller) is None


def test_an_environment_of_your_own_is_a_grid_axis_with_parameters_of_its_own():
    from pizero_ray.cli.experiments import _env_scoped_arg

    assert _env_scoped_arg("examples.corridor:make:length=5") == ("examples.corridor:make", ("length", 5))
    assert _env_scoped_arg("sokoban:levels=/data/a:b") == ("sokoban", ("levels", "/data/a:b"))
    experiment = _experiment(envs=("tsp", "examples.corridor:make"),
                             env_args=(("examples.corridor:make", (("length", 5),)),), eval_env_args=())
    config = experiment.config(grid.Trial("examples.corridor:make", "pizero", 0))
    assert config.env == "examples.corridor:make" and dict(config.env_args) == {"length": 5}
    grid.check(experiment)  # builds (and checks) the corridor with length 5: no error
    with pytest.raises(ConfigError, match="--envs: unknown environment 'corridor'; choose from 2048"):
        _experiment(envs=("corridor",), env_args=(), eval_env_args=())
