"""The layers, checked: the math imports neither Ray nor Orbax, storage builds no method, and loading a run
needs no Ray."""

import json
import os
import subprocess
import sys
from pathlib import Path

REPO = str(Path(__file__).resolve().parents[1])  # this checkout, not whichever one pip installed

MATH = ["pizero_ray.config", "pizero_ray.settings", "pizero_ray.presets",
        "pizero_ray.agent", "pizero_ray.agent.networks", "pizero_ray.agent.planner",
        "pizero_ray.agent.decoder", "pizero_ray.agent.pizero", "pizero_ray.agent.episodes", "pizero_ray.es",
        "pizero_ray.es.noise", "pizero_ray.es.shaping", "pizero_ray.es.strategy", "pizero_ray.es.population",
        "pizero_ray.baselines", "pizero_ray.baselines.networks", "pizero_ray.baselines.search",
        "pizero_ray.baselines.replay", "pizero_ray.baselines.losses", "pizero_ray.baselines.learner",
        "pizero_ray.envs", "pizero_ray.envs.discretised"]


def _compiler_flags() -> dict[str, str]:
    """The XLA flags conftest set for the tests (a faster compile): they decide nothing about imports."""
    return {"XLA_FLAGS": os.environ["XLA_FLAGS"]} if "XLA_FLAGS" in os.environ else {}


def _loaded_after_importing(modules: list[str]) -> set[str]:
    """Top-level packages in sys.modules after importing ``modules`` in a fresh interpreter."""
    code = ("import importlib, json, sys\n"
            f"for name in {modules!r}: importlib.import_module(name)\n"
            "print(json.dumps(sorted({m.split('.')[0] for m in sys.modules} | "
            "{m for m in sys.modules if m.startswith('pizero_ray.')})))")
    env_vars = {"JAX_PLATFORMS": "cpu", "PATH": "/usr/bin:/bin", "PYTHONPATH": REPO}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env_vars)
    return set(json.loads(out.stdout))


def test_the_math_imports_neither_ray_nor_orbax_nor_the_shell():
    loaded = _loaded_after_importing(MATH)
    assert "jax" in loaded and "mctx" in loaded  # the check sees real imports
    assert not {"ray", "orbax"} & loaded
    shell = {m for m in loaded if m.startswith(("pizero_ray.trainer", "pizero_ray.storage", "pizero_ray.cli"))}
    assert not shell


def test_storage_imports_neither_the_agent_nor_mctx():
    """Storage saves, restores and hashes a run's state; building a method is ``pizero_ray.methods``' job."""
    loaded = _loaded_after_importing(["pizero_ray.storage", "pizero_ray.storage.checkpoints",
                                      "pizero_ray.storage.run_dir", "pizero_ray.storage.runs",
                                      "pizero_ray.storage.tensorboard"])
    assert "pizero_ray.storage.runs" in loaded  # the check sees real imports
    assert not {"mctx", "ray"} & loaded
    assert not {m for m in loaded if m.startswith(("pizero_ray.agent", "pizero_ray.es", "pizero_ray.baselines",
                                                    "pizero_ray.methods", "pizero_ray.trainer", "pizero_ray.cli"))}


def test_the_run_options_are_pure_dataclasses():
    """The CLI builds its options from them for every command: they import neither Ray nor JAX."""
    loaded = _loaded_after_importing(["pizero_ray.trainer.options"])
    assert not {"ray", "orbax", "jax"} & loaded
    assert {m for m in loaded if m.startswith("pizero_ray.trainer.")} == {
        "pizero_ray.trainer.options", "pizero_ray.trainer.compile_cache"}


def test_evaluating_a_saved_run_imports_neither_ray_nor_the_trainer(tmp_path):
    """eval, render and inspect load a run through storage: a checkpoint is read without Ray."""
    code = f"""
import json, sys
from pathlib import Path
from pizero_ray import envs
from pizero_ray.config import build_config
from pizero_ray import methods
from pizero_ray.storage import checkpoints, run_dir, runs
from pizero_ray.evaluation.runs import evaluate_run
path = Path({str(tmp_path)!r})
config = build_config("tiny", env="tsp", planner="none")
run_dir.write_config(path, config)
state, _, _ = methods.initial_state(config, envs.make("tsp"))
writer = checkpoints.CheckpointWriter(path)
runs.save(writer, config, state._replace(iteration=3))
writer.close()
result = evaluate_run(path, episodes=4, seed=0)
loaded = {{m.split(".")[0] for m in sys.modules}} | {{m for m in sys.modules if m.startswith("pizero_ray.")}}
print(json.dumps({{"iteration": result["iteration"], "loaded": sorted(loaded)}}))
"""
    env_vars = {"JAX_PLATFORMS": "cpu", "PATH": "/usr/bin:/bin", "PYTHONPATH": REPO, **_compiler_flags()}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env_vars)
    assert out.returncode == 0, out.stderr[-2000:]
    report = json.loads(out.stdout.strip().splitlines()[-1])
    assert report["iteration"] == 3  # the checkpoint was read (through Orbax) ...
    assert "orbax" in report["loaded"]
    assert "ray" not in report["loaded"]  # ... without Ray
    assert not [m for m in report["loaded"] if m.startswith("pizero_ray.trainer")]
