"""docs/api.md: every Python example on the page runs, in order, in one fresh directory, in one process (the
page's runs are the later examples' inputs). One Ray instance serves the page's trainings."""

import os
import re
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
PAGE = REPO / "docs" / "api.md"


def examples() -> list[str]:
    return re.findall(r"```python\n(.*?)```", PAGE.read_text(), flags=re.S)


def test_the_page_has_its_examples():
    assert len(examples()) >= 4


def test_every_example_on_the_page_runs(tmp_path):
    script = "\n\n".join(f"# example {number}\n{code}" for number, code in enumerate(examples(), 1))
    env = {**os.environ, "PYTHONPATH": str(REPO), "JAX_PLATFORMS": "cpu"}
    done = subprocess.run([sys.executable, "-c", script], cwd=tmp_path, env=env, capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    printed = done.stdout.splitlines()
    assert printed[0].startswith("3 ")  # the first run's iteration and hash
    assert (tmp_path / "runs" / "api-tsp" / "config.json").is_file()
    assert len(list((tmp_path / "runs" / "api-sweep").iterdir())) == 2


def test_the_package_names_its_api_without_loading_jax_or_ray():
    code = ("import sys, pizero_ray; print(pizero_ray.__version__, sorted(pizero_ray.__all__), "
            "'jax' in sys.modules, 'ray' in sys.modules)")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env={**os.environ, "PYTHONPATH": str(REPO)})
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip().endswith("False False")
    assert "'load_agent'" in out.stdout and "'train'" in out.stdout
