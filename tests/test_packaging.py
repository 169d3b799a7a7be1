"""The project installs one top-level package, pizero_ray: an `envs` of another project's is never shadowed."""

import subprocess
import sys
import tomllib
from pathlib import Path

from setuptools import find_packages

REPO = Path(__file__).resolve().parents[1]


def test_the_packages_installed_are_all_under_pizero_ray():
    found = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]["packages"]["find"]
    packages = find_packages(str(REPO), include=found["include"])
    assert "pizero_ray.envs" in packages
    assert all(name == "pizero_ray" or name.startswith("pizero_ray.") for name in packages), packages


def test_outside_the_checkout_a_package_named_envs_is_someone_elses(tmp_path):
    (tmp_path / "envs").mkdir()
    (tmp_path / "envs" / "__init__.py").write_text("OWNER = 'another project'\n")
    code = "import envs, pizero_ray.envs; print(envs.OWNER, len(pizero_ray.envs.ENV_NAMES))"
    done = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.split() == ["another", "project", "8"]
    alone = subprocess.run([sys.executable, "-c", "import envs"], cwd=tmp_path.parent, capture_output=True, text=True)
    assert alone.returncode != 0 and "No module named 'envs'" in alone.stderr
