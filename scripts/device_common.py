"""What the GPU-machine scripts share (scripts/device_check.py, scripts/device_run.py): the interpreter and its
wheels, running a step to its deadline, and the one JSON report saved after every step.

Not a package: each script runs as ``python3 scripts/<name>.py``, which puts this folder on sys.path.
"""

from __future__ import annotations

import datetime
import json
import os
import re
import shutil
import signal
import subprocess
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def gpu_names() -> list[str]:
    """The NVIDIA GPUs nvidia-smi lists ([] where there is none, or no driver)."""
    if shutil.which("nvidia-smi") is None:
        return []
    try:
        listed = subprocess.run(["nvidia-smi", "--query-gpu=name,memory.total", "--format=csv,noheader"],
                                capture_output=True, text=True, timeout=60)
    except (OSError, subprocess.TimeoutExpired):
        return []
    return [line.strip() for line in listed.stdout.splitlines() if line.strip()] if listed.returncode == 0 else []


def run(command: list[str], env: dict, timeout_s: float, log: Path | None = None) -> dict:
    """Runs a command to completion or its deadline; its outcome, time and output tail."""
    started = time.time()
    with tempfile.TemporaryFile("w+") as output:
        process = subprocess.Popen(command, cwd=ROOT, env=env, stdout=output, stderr=subprocess.STDOUT, text=True,
                                   start_new_session=True)
        try:
            code = process.wait(timeout=max(timeout_s, 1.0))
        except subprocess.TimeoutExpired:
            os.killpg(process.pid, signal.SIGKILL)
            code = process.wait()
        output.seek(0)
        text = output.read()
    if log is not None:
        log.write_text(text)
    timed_out = time.time() - started >= timeout_s
    return {"command": " ".join(command), "exit_code": code, "timed_out": timed_out,
            "seconds": round(time.time() - started, 1), "output_tail": text[-3000:]}


def stop(process: subprocess.Popen, grace_s: float = 60.0) -> str:
    """SIGTERMs a training still running (pizero saves a checkpoint and exits), gives it ``grace_s``, then
    SIGKILLs its process group; returns its output (``process`` was started with stdout piped and
    ``start_new_session``)."""
    if process.poll() is None:
        process.send_signal(signal.SIGTERM)
    try:
        text, _ = process.communicate(timeout=grace_s)
    except subprocess.TimeoutExpired:
        os.killpg(process.pid, signal.SIGKILL)
        text, _ = process.communicate()
    return text


def install_wheels(python: str, wheels: Path, target: Path) -> list[str]:
    """Installs the wheels in ``wheels`` whose package ``python`` lacks (or has older) into ``target``."""
    probe = ("import importlib.metadata as m, sys\n"
             "from packaging.version import Version\n"
             "name, version = sys.argv[1:]\n"
             "try:\n    sys.exit(0 if Version(m.version(name)) >= Version(version) else 1)\n"
             "except m.PackageNotFoundError:\n    sys.exit(1)\n")
    needed = []
    for wheel in sorted(wheels.glob("*.whl")):
        name, version = wheel.name.split("-")[:2]
        if subprocess.run([python, "-c", probe, name, version]).returncode != 0:
            needed.append(wheel)
    if needed:
        subprocess.run([python, "-m", "pip", "install", "-q", "--no-index", "--no-deps", "--no-compile",
                        "--target", str(target), *map(str, needed)], check=True)
    return [wheel.name for wheel in needed]


def python_environment(args, tool: str = "device-check") -> tuple[str, dict, dict]:
    """(interpreter, environment for every step, what was installed): ``args.python`` (with ``args.wheels``),
    else the gpu extra installed into .venv; JAX on the CPU alone with ``args.cpu_rehearsal``."""
    env = {**os.environ, "JAX_PLATFORMS": "cpu" if args.cpu_rehearsal else "cuda,cpu",
           "XLA_PYTHON_CLIENT_PREALLOCATE": "false",  # the driver and the workers share the GPU
           "RAY_USAGE_STATS_ENABLED": "0", "PYTHONUNBUFFERED": "1"}
    env.pop("RAY_ADDRESS", None)
    installed: dict = {}
    if args.python:
        python = args.python
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH")]))
    else:
        subprocess.run(["make", "-C", str(ROOT), "install"], check=True)
        python = str(ROOT / ".venv" / "bin" / "python")
        subprocess.run([python, "-m", "pip", "install", "-q", "-e", f"{ROOT}[gpu]"], check=True)
        installed["gpu_extra"] = True
    if args.wheels:
        target = Path(tempfile.mkdtemp(prefix="pizero-device-site-"))
        installed["wheels"] = install_wheels(python, Path(args.wheels), target)
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(target), env.get("PYTHONPATH")]))
    versions = subprocess.run(
        [python, "-c", "import jax, ray, mctx, optax, orbax.checkpoint as o, sys; print(sys.version.split()[0], "
         "jax.__version__, ray.__version__, mctx.__version__, optax.__version__, o.__version__, "
         "[str(d) for d in jax.devices()])"], env=env, capture_output=True, text=True, timeout=300)
    installed["versions"] = (versions.stdout or versions.stderr).strip().splitlines()[-1:]
    if versions.returncode != 0:
        raise SystemExit(f"{tool}: {python} cannot import the project's dependencies: {versions.stderr[-500:]}")
    return python, env, installed


def last_json(text: str):
    """The last line of ``text`` that is a JSON object (what `pizero train`, `eval --json` and `bench --json`
    print last), or None."""
    for line in reversed(text.strip().splitlines()):
        if line.startswith("{"):
            try:
                return json.loads(line)
            except json.JSONDecodeError:  # a line cut off by the output's tail
                continue
    return None


def commit() -> str:
    """The commit the tree is at: PIZERO_COMMIT (a copy of the tree without .git says so), else git's."""
    if os.environ.get("PIZERO_COMMIT"):
        return os.environ["PIZERO_COMMIT"]
    try:
        head = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True, text=True)
    except OSError:  # no git on the machine
        return "unknown"
    return head.stdout.strip() or "unknown"


def report_header(gpus: list[str], installed: dict) -> dict:
    """What every report opens with: the date, the machine and the code."""
    return {"date": datetime.date.today().isoformat(), "gpus": gpus or ["none (CPU rehearsal)"],
            "cpu_cores": os.cpu_count(), "python": installed, "commit": commit()}


def report_path(out: str | Path, report: dict, what: str) -> Path:
    """``OUT/<date>-<what>-<gpu kind>.json``, the kind from the first GPU's name (e.g. nvidia-h200)."""
    kind = re.sub(r"[^a-z0-9]+", "-", report["gpus"][0].split(",")[0].lower()).strip("-")
    return Path(out) / f"{report['date']}-{what}-{kind}.json"


def save_report(path: Path, report: dict) -> Path:
    """Writes the report so far: a step that hangs past the command's own limit still leaves the others'."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(report, indent=2, sort_keys=True) + "\n")
    return path
