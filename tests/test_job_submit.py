"""`ray job submit` against a `ray start --head` instance, and the README's cluster walkthrough, with HOME empty."""

import json
import os
import secrets
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]
BIN = Path(sys.executable).parent


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def head_node():
    """A separate Ray head (GCS, dashboard, job server) of its own, stopped by signalling its process group."""
    temp_dir = tempfile.mkdtemp(prefix="rj", dir="/tmp")  # short: Ray's socket paths must fit in 107 bytes
    gcs_port, dashboard_port = _free_port(), _free_port()
    # This head's own token, made here: nothing may come from an earlier run's ~/.ray (HOME is empty).
    token_path = Path(temp_dir) / "auth_token"
    token_path.write_text(secrets.token_hex(32))
    home = Path(temp_dir) / "home"
    home.mkdir()
    env = {**os.environ, "PATH": f"{BIN}:{os.environ['PATH']}", "RAY_USAGE_STATS_ENABLED": "0",
           "JAX_PLATFORMS": "cpu", "HOME": str(home), "RAY_AUTH_TOKEN_PATH": str(token_path),
           # Clients of a token-authenticated cluster (`ray job ...`) send their token only in token mode.
           "RAY_AUTH_MODE": "token"}
    for name in ("RAY_ADDRESS", "RAY_AUTH_TOKEN"):
        env.pop(name, None)
    head = subprocess.Popen(
        [str(BIN / "ray"), "start", "--head", "--block", f"--port={gcs_port}", "--num-cpus=2",
         "--object-store-memory=100000000", "--include-dashboard=true", "--dashboard-host=127.0.0.1",
         f"--dashboard-port={dashboard_port}", f"--temp-dir={temp_dir}",
         # Free ports for everything else too: the session's own cluster already holds Ray's defaults.
         f"--ray-client-server-port={_free_port()}", f"--dashboard-agent-listen-port={_free_port()}",
         f"--dashboard-agent-grpc-port={_free_port()}", f"--runtime-env-agent-port={_free_port()}",
         f"--metrics-export-port={_free_port()}"],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, start_new_session=True,
    )
    address = f"http://127.0.0.1:{dashboard_port}"
    try:
        deadline = time.time() + 180
        while time.time() < deadline:
            probe = subprocess.run([str(BIN / "ray"), "job", "list", "--address", address], env=env,
                                   capture_output=True, text=True)
            if probe.returncode == 0:
                break
            assert head.poll() is None, head.stdout.read()
            time.sleep(2)
        else:
            pytest.fail(f"the Ray head's job server never came up: {probe.stderr[-2000:]}")
        yield address, env
    finally:
        os.killpg(head.pid, signal.SIGTERM)  # --block: the head tears its cluster down on SIGTERM
        try:
            head.wait(timeout=60)
        except subprocess.TimeoutExpired:
            os.killpg(head.pid, signal.SIGKILL)


@pytest.mark.slow
def test_job_submit_runs_a_training(head_node, tmp_path, compile_cache_dir):
    address, env = head_node
    run_dir = tmp_path / "job-run"  # absolute: the job runs in a temporary working dir
    command = [str(BIN / "ray"), "job", "submit", "--address", address, "--working-dir", str(REPO), "--",
               "pizero", "train", "--env", "tsp", "--preset", "tiny", "--iterations", "2", "--workers", "1",
               "--run-dir", str(run_dir), "--compile-cache", compile_cache_dir, "--no-progress"]
    for _ in range(60):
        submit = subprocess.run(command, env=env, capture_output=True, text=True, timeout=600)
        # The job server answers before the head's agent can take jobs; Ray says so and asks to retry.
        if "No available agent to submit job" not in submit.stdout + submit.stderr:
            break
        time.sleep(2)
    assert submit.returncode == 0, submit.stdout + submit.stderr
    assert "succeeded" in submit.stdout.lower()
    rows = [json.loads(line) for line in (run_dir / "metrics.jsonl").read_text().splitlines()]
    assert [row["iteration"] for row in rows] == [1, 2]
    inspect = subprocess.run([str(BIN / "pizero"), "inspect", str(run_dir), "--json"], env=env,
                             capture_output=True, text=True, check=True)
    assert json.loads(inspect.stdout)["iteration"] == 2


@pytest.mark.slow
def test_the_readme_cluster_walkthrough_works_with_an_empty_home(tmp_path):
    """`cluster/local-cluster.sh start`, `cluster/submit-example.sh`, `stop`, as the README has them, HOME empty.

    The start script must make the token the cluster needs; nothing may come
    from an earlier run's ~/.ray or compile cache.
    """
    home = tmp_path / "home"
    home.mkdir()
    temp_dir = tempfile.mkdtemp(prefix="lc", dir="/tmp")  # short: Ray's socket paths must fit in 107 bytes
    ports = ("PIZERO_RAY_PORT", "PIZERO_DASHBOARD_PORT", "PIZERO_CLIENT_PORT", "PIZERO_HEAD_AGENT_PORT",
             "PIZERO_WORKER_AGENT_PORT")
    env = {**os.environ, "HOME": str(home), "PIZERO_RAY_TEMP_DIR": temp_dir, "JAX_PLATFORMS": "cpu",
           **{name: str(_free_port()) for name in ports}}
    for name in ("RAY_ADDRESS", "RAY_AUTH_TOKEN", "RAY_AUTH_TOKEN_PATH", "RAY_AUTH_MODE"):
        env.pop(name, None)
    script = REPO / "cluster" / "local-cluster.sh"
    try:
        start = subprocess.run(["bash", str(script), "start"], env=env, capture_output=True, text=True, timeout=300)
        assert start.returncode == 0, start.stdout + start.stderr
        assert (home / ".ray" / "auth_token").is_file()  # made by the script, in the empty HOME
        run_dir = tmp_path / "example"
        example = subprocess.run(["bash", str(REPO / "cluster" / "submit-example.sh"), str(run_dir)], env=env,
                                 capture_output=True, text=True, timeout=900)
        assert example.returncode == 0, example.stdout[-3000:] + example.stderr[-3000:]
        assert f"Done: {run_dir} holds 200 iterations." in example.stdout
        rows = [json.loads(line) for line in (run_dir / "metrics.jsonl").read_text().splitlines()]
        assert [row["iteration"] for row in rows] == list(range(1, 201))
    finally:
        stop = subprocess.run(["bash", str(script), "stop"], env=env, capture_output=True, text=True, timeout=120)
        assert stop.returncode == 0, stop.stdout + stop.stderr
