"""Bad input: one line on stderr naming the value, exit code 2, nothing written."""

import pytest

from pizero_ray.cli import main


def _run(argv, capsys):
    try:
        code = main(argv)
    except SystemExit as exit_:  # argparse's own errors
        code = exit_.code
    err = capsys.readouterr().err.strip().splitlines()
    return code, err


@pytest.mark.parametrize(
    "extra, named",
    [
        (["--env", "chess"], "'chess'"),
        (["--population", "0"], "population must be a positive integer, got 0"),
        (["--population", "-3"], "got -3"),
        (["--population", "10", "--chunk-size", "4"], "population 10 is not a multiple of chunk_size 4"),
        (["--planner", "alphabeta"], "'alphabeta'"),
        (["--sigma", "0"], "sigma must be positive, got 0.0"),
        (["--perturbation-rank", "-1"], "perturbation_rank must be a non-negative integer, got -1"),
        (["--env-arg", "num_cities=1"], "tsp: num_cities must be an integer at least 3, got 1"),
        (["--env-arg", "cities=3"], "bad parameters for environment 'tsp'"),
        (["--preset", "huge"], "unknown preset 'huge'"),
        (["--decoder-inputs", "state,mood"], "unknown decoder input 'mood'"),
        (["--iterations", "0"], "expected a positive integer, got '0'"),
    ],
)
def test_bad_train_input_is_one_line_and_writes_nothing(tmp_path, capsys, extra, named):
    run_dir = tmp_path / "run"
    code, err = _run(["train", "--run-dir", str(run_dir), *extra], capsys)
    assert code == 2
    # The last line is the error, naming the value: ours ("pizero: error: ...") or argparse's, after its usage.
    assert err[-1].startswith(("pizero: error: ", "pizero train: error: ")), err
    assert named in err[-1], err
    assert not run_dir.exists()


def test_our_own_errors_are_exactly_one_line(tmp_path, capsys):
    code, err = _run(["train", "--run-dir", str(tmp_path / "r"), "--population", "0"], capsys)
    assert code == 2 and len(err) == 1 and err[0].startswith("pizero: error:")


@pytest.mark.parametrize("command", ["eval", "inspect", "resume"])
def test_missing_run_dir(tmp_path, capsys, command):
    missing = tmp_path / "nowhere"
    argv = [command, str(missing)] + (["--iterations", "2"] if command == "resume" else [])
    code, err = _run(argv, capsys)
    assert code == 2 and len(err) == 1
    assert str(missing) in err[0] and "does not exist" in err[0]
    assert not missing.exists()


def test_directory_without_config_is_not_a_run(tmp_path, capsys):
    code, err = _run(["inspect", str(tmp_path)], capsys)
    assert code == 2 and "is not a pizero run dir" in err[0]


def test_train_refuses_to_overwrite_a_run(tmp_path, capsys):
    from pizero_ray.config import build_config
    from pizero_ray.storage import run_dir

    run_dir.write_config(tmp_path, build_config("tiny"))
    before = (tmp_path / "config.json").read_text()
    code, err = _run(["train", "--run-dir", str(tmp_path), "--preset", "tiny"], capsys)
    assert code == 2 and "pizero resume" in err[0]
    assert (tmp_path / "config.json").read_text() == before


@pytest.mark.parametrize("extra", [["--simulations", "1,0"], ["--populations", "64,x"], ["--simulations", ""]])
def test_bad_bench_sweeps_are_one_line_errors(capsys, extra):
    code, err = _run(["bench", "--quick", *extra], capsys)
    assert code == 2
    assert any(repr(extra[1]) in line and "positive integers" in line for line in err), err
