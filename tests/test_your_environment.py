"""Your own environment end to end (docs/your-environment.md): examples/corridor.py trained by import path through
the `pizero` console script (a fresh process and Ray instance, one real worker), evaluated and rendered; and an
environment that cannot be built or breaks the protocol is one line, with nothing written."""

import json
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from examples import corridor
from pizero_ray.cli import main
from pizero_ray.config import build_config
from pizero_ray.storage import run_dir

REPO = Path(__file__).resolve().parents[1]
PIZERO = Path(sys.executable).parent / "pizero"
EXAMPLE = "examples.corridor:make"


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """(run dir, the finished `pizero train`), run in the checkout: `examples` is importable from there only
    (the console script's sys.path has neither the checkout nor the working directory)."""
    run = tmp_path_factory.mktemp("corridor") / "run"
    command = [str(PIZERO), "train", "--env", EXAMPLE, "--env-arg", "length=5", "--run-dir", str(run),
               "--preset", "tiny", "--planner", "none", "--population", "2", "--chunk-size", "2",
               "--iterations", "2", "--workers", "1", "--eval-every", "0", "--no-progress"]
    return run, subprocess.run(command, cwd=REPO, capture_output=True, text=True, timeout=300)


def test_the_example_trains_by_import_path_on_a_real_worker(trained):
    run, finished = trained
    assert finished.returncode == 0, finished.stderr[-3000:]
    assert "local Ray instance, asking for 1 worker," in finished.stderr
    assert json.loads(finished.stdout.strip().splitlines()[-1])["iteration"] == 2
    config = run_dir.read_config(run)  # the import path is recorded, for eval, render and resume
    assert config.env == EXAMPLE and dict(config.env_args) == {"length": 5}


def test_the_trained_example_evaluates_and_renders(trained, tmp_path, capsys):
    run, finished = trained
    assert finished.returncode == 0, finished.stderr[-3000:]
    assert main(["eval", str(run), "--episodes", "8", "--json", "--env", EXAMPLE]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["env"] == EXAMPLE and result["iteration"] == 2
    assert 0.0 <= result["mean_arrived"] <= 1.0  # the example's episode_metrics hook
    out = tmp_path / "corridor.png"
    assert main(["render", str(run), "--out", str(out), "--trust-env"]) == 0
    frame = np.asarray(Image.open(out).convert("RGB"))
    assert frame.shape[1] == 480  # 5 cells of 16 pixels, made legible (x6)
    assert (frame == corridor.AGENT).all(-1).any() and (frame == corridor.GOAL).all(-1).any()  # drawn by render


@pytest.mark.parametrize("env, problem", [
    ("nosuchmodule:make", "environment 'nosuchmodule:make': no module named 'nosuchmodule' in "),
    ("pizero_ray.envs.tsp:nosuchattr", "has no attribute 'nosuchattr'"),
    ("examples.corridor:", "an import path must read module:factory"),
])
def test_an_environment_that_cannot_be_built_is_one_line_and_writes_nothing(tmp_path, capsys, env, problem):
    run = tmp_path / "run"
    code = main(["train", "--run-dir", str(run), "--env", env, "--preset", "tiny"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1 and err[0].startswith("pizero: error: ") and problem in err[0], err
    assert not run.exists()


BROKEN = """
    import jax.numpy as jnp
    from examples import corridor

    def make():
        env = corridor.make()

        def step(state, action):
            if action == corridor.RIGHT:  # Python control flow on a traced value
                return env.step(state, action)
            return env.step(state, jnp.int32(corridor.LEFT))

        return env._replace(step=step)
"""


def test_an_environment_that_breaks_the_protocol_is_one_line_before_anything_trains(tmp_path, monkeypatch, capsys):
    (tmp_path / "broken_corridor.py").write_text(textwrap.dedent(BROKEN))
    monkeypatch.chdir(tmp_path)  # where `pizero` runs: the module is found there
    monkeypatch.setattr(sys, "path", list(sys.path))  # restored after the test
    monkeypatch.delitem(sys.modules, "broken_corridor", raising=False)
    code = main(["train", "--run-dir", str(tmp_path / "run"), "--env", "broken_corridor:make", "--preset", "tiny"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == 2 and len(err) == 1, err
    assert err[0].startswith("pizero: error: environment 'broken_corridor:make': step is not jittable")
    assert not (tmp_path / "run").exists()
    sys.modules.pop("broken_corridor", None)


def test_eval_of_a_run_whose_environment_is_not_importable_here_is_one_line(tmp_path, capsys):
    run_dir.write_config(tmp_path, build_config("tiny", env="moved_away_module:make"))
    assert main(["eval", str(tmp_path), "--trust-env"]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "environment 'moved_away_module:make': no module named 'moved_away_module'" in err[0]
