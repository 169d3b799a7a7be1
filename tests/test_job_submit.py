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
import sys
import tempfile
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent  # this environment's ray and pizero commands
TARGET = 40  # iterations the example reaches (200 in the README); its second job is stopped after 15
# The node-loss runs: long enough that the second node's worker joins and then loses its node mid-run.
NODE_LOSS_TRAIN = ["pizero", "train", "--env", "tsp", "--preset", "tiny", "--population", "64", "--chunk-size", "16",
                   "--iterations", "300", "--workers", "2", "--checkpoint-every", "0", "--no-progress"]


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
            done["rows"] = _rows(done["run_dir"])
            done.update(_lose_the_second_node(env, base, script))
    finally:
        done["stop"] = subprocess.run(["bash", str(script), "stop"], env=env, capture_output=True, text=True,
                                      timeout=120)
    return done


def _rows(run_dir: Path) -> list[dict]:
    metrics = run_dir / "metrics.jsonl"
    return [json.loads(line) for line in metrics.read_text().splitlines()] if metrics.exists() else []


def _lose_the_second_node(env: dict, base: Path, script: Path) -> dict:
    """An undisturbed run, then the same run as a job whose second node is removed mid-run
    (``local-cluster.sh stop-second``, what ``ray stop`` does on that node's own machine)."""
    env = {**env, "RAY_AUTH_MODE": "token"}  # as the cluster's scripts set it; the token is in HOME
    address = f"http://127.0.0.1:{env['PIZERO_DASHBOARD_PORT']}"
    submit = [str(BIN / "ray"), "job", "submit", "--address", address, "--working-dir", str(REPO)]
    undisturbed, lost = base / "undisturbed", base / "node-loss"
    done = {"undisturbed": subprocess.run([*submit, "--", *NODE_LOSS_TRAIN, "--run-dir", str(undisturbed)],
                                          env=env, capture_output=True, text=True, timeout=600)}
    job = subprocess.Popen([*submit, "--", *NODE_LOSS_TRAIN, "--run-dir", str(lost)], env=env,
                           stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.monotonic() + 300
        while job.poll() is None and time.monotonic() < deadline:
            rows = _rows(lost)
            if rows and rows[-1]["workers"] == 2:  # both nodes' workers have scored an iteration
                done["stopped_after"] = rows[-1]["iteration"]
                done["stop_second"] = subprocess.run(["bash", str(script), "stop-second"], env=env,
                                                     capture_output=True, text=True, timeout=120)
                break
            time.sleep(0.1)
        done["node_loss_log"] = job.communicate(timeout=600)[0]  # the job's own output, to its end
    finally:
        if job.poll() is None:
            job.kill()
    done["node_loss"] = job.returncode
    done["node_loss_rows"] = _rows(lost)
    done["hashes"] = [_parameter_hash(env, path) for path in (undisturbed, lost)]
    return done


def _parameter_hash(env: dict, run_dir: Path) -> str | None:
    inspect = subprocess.run([str(BIN / "pizero"), "inspect", "--json", str(run_dir)], env=env,
                             capture_output=True, text=True, timeout=300)
    return json.loads(inspect.stdout)["parameter_hash"] if inspect.returncode == 0 else None


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
        _check_the_second_node_lost(done)
    finally:
        stop = done["stop"]
        assert stop.returncode == 0, stop.stdout + stop.stderr


def _check_the_second_node_lost(done: dict) -> None:
    """The run that lost its second node mid-run finished every iteration, on one worker after the loss,
    with the undisturbed run's parameters."""
    undisturbed = done["undisturbed"]
    assert undisturbed.returncode == 0, undisturbed.stdout[-3000:] + undisturbed.stderr[-3000:]
    assert "stopped_after" in done, "the second node's worker never scored before the run ended:\n" + \
        done["node_loss_log"][-3000:]
    stop = done["stop_second"]
    assert stop.returncode == 0, stop.stdout + stop.stderr
    assert done["node_loss"] == 0, done["node_loss_log"][-3000:]
    rows = done["node_loss_rows"]
    assert [row["iteration"] for row in rows] == list(range(1, 301))
    after = [row for row in rows if row["iteration"] > done["stopped_after"]]
    assert after and sum(row["workers_lost"] for row in after) >= 1  # the loss happened mid-run, and was seen
    assert after[-1]["workers"] == 1  # the rest ran on the head's worker alone
    assert done["hashes"][0] is not None and done["hashes"][0] == done["hashes"][1]
