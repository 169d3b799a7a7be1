"""`ray job submit` against a `ray start --head` instance runs a training to completion."""

import json
import os
import signal
import socket
import subprocess
import sys
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
    import tempfile

    temp_dir = tempfile.mkdtemp(prefix="rj", dir="/tmp")  # short: Ray's socket paths must fit in 107 bytes
    gcs_port, dashboard_port = _free_port(), _free_port()
    env = {**os.environ, "PATH": f"{BIN}:{os.environ['PATH']}", "RAY_USAGE_STATS_ENABLED": "0",
           "JAX_PLATFORMS": "cpu",
           # Clients of a token-authenticated cluster (`ray job ...`) send ~/.ray/auth_token only in token mode.
           "RAY_AUTH_MODE": "token"}
    env.pop("RAY_ADDRESS", None)
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
