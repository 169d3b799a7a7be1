"""The README's cluster walkthrough, with HOME empty: `ray start --head` nodes, `ray job submit`, stop, resume.

The walkthrough takes minutes and is mostly waiting (Ray's CLI, the jobs'
start-ups, the nodes' shutdown), so conftest.py's ``readme_walkthrough``
fixture starts ``run_walkthrough`` in a background thread as the session
begins, when this test is selected (under pytest-xdist, in the first worker
to claim it): it overlaps the other tests. The test waits for it and checks
what it did.
"""

import json
import os
import socket
import subprocess
import tempfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
TARGET = 40  # iterations the example reaches (200 in the README); its second job is stopped after 15


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def run_walkthrough(base: Path) -> dict:
    """`cluster/local-cluster.sh start`, `cluster/submit-example.sh`, `stop`, as the README has them, HOME empty.

    Returns each step's CompletedProcess, whether the start made the token in
    the empty HOME, and the example run's metrics rows; it checks nothing
    (the test does). The cluster is stopped whatever happened.
    """
    home = base / "home"
    home.mkdir()
    temp_dir = tempfile.mkdtemp(prefix="lc", dir="/tmp")  # short: Ray's socket paths must fit in 107 bytes
    ports = ("PIZERO_RAY_PORT", "PIZERO_DASHBOARD_PORT", "PIZERO_CLIENT_PORT", "PIZERO_HEAD_AGENT_PORT",
             "PIZERO_WORKER_AGENT_PORT")
    env = {**os.environ, "HOME": str(home), "PIZERO_RAY_TEMP_DIR": temp_dir, "JAX_PLATFORMS": "cpu",
           "PIZERO_EXAMPLE_TARGET": str(TARGET), **{name: str(_free_port()) for name in ports}}
    for name in ("RAY_ADDRESS", "RAY_AUTH_TOKEN", "RAY_AUTH_TOKEN_PATH", "RAY_AUTH_MODE"):
        env.pop(name, None)
    script = REPO / "cluster" / "local-cluster.sh"
    done = {"run_dir": base / "example"}
    try:
        done["start"] = subprocess.run(["bash", str(script), "start"], env=env, capture_output=True, text=True,
                                       timeout=300)
        done["token_made"] = (home / ".ray" / "auth_token").is_file()  # by the script, in the empty HOME
        if done["start"].returncode == 0:
            done["example"] = subprocess.run(["bash", str(REPO / "cluster" / "submit-example.sh"),
                                              str(done["run_dir"])], env=env, capture_output=True, text=True,
                                             timeout=900)
            metrics = done["run_dir"] / "metrics.jsonl"
            if metrics.exists():
                done["rows"] = [json.loads(line) for line in metrics.read_text().splitlines()]
    finally:
        done["stop"] = subprocess.run(["bash", str(script), "stop"], env=env, capture_output=True, text=True,
                                      timeout=120)
    return done


@pytest.mark.slow
@pytest.mark.readme_walkthrough
def test_the_readme_cluster_walkthrough_works_with_an_empty_home(readme_walkthrough):
    """The start script must make the token the cluster needs; nothing may come
    from an earlier run's ~/.ray or compile cache."""
    done = readme_walkthrough.result()  # run_walkthrough, started as the session began: wait for its end
    try:
        start = done["start"]
        assert start.returncode == 0, start.stdout + start.stderr
        assert done["token_made"]  # made by the script, in the empty HOME
        run_dir, example = done["run_dir"], done["example"]
        assert example.returncode == 0, example.stdout[-3000:] + example.stderr[-3000:]
        assert f"Done: {run_dir} holds {TARGET} iterations." in example.stdout
        assert "pizero: stopped by SIGTERM after iteration" in example.stdout  # the second job, part-way
        assert [row["iteration"] for row in done["rows"]] == list(range(1, TARGET + 1))
    finally:
        stop = done["stop"]
        assert stop.returncode == 0, stop.stdout + stop.stderr
