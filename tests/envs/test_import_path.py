"""Environments by import path: found from the working directory first, checked, and every failure one line."""

import sys
import textwrap

import pytest

from pizero_ray import envs
from pizero_ray.envs import import_path

# A module of the user's, written into the working directory each test runs in (tmp_path).
FACTORIES = """
    from examples import corridor

    def make(length=8):
        return corridor.make(length)

    def not_an_environment():
        return "corridor"

    def strict(length=8):
        if length > 9:
            raise ValueError("too\\nlong")
        return corridor.make(length)

    value = 3
"""


@pytest.fixture
def user_module(tmp_path, monkeypatch):
    """A fresh module name in a fresh working directory that is not on sys.path, as where `pizero` runs."""
    name = f"user_envs_{tmp_path.name.replace('-', '_')}"
    (tmp_path / f"{name}.py").write_text(textwrap.dedent(FACTORIES))
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys, "path", [p for p in sys.path if p not in ("", str(tmp_path))])  # restored after
    yield name
    sys.modules.pop(name, None)


def test_a_module_in_the_working_directory_is_imported_and_its_factory_gets_the_env_args(user_module):
    env = envs.make(f"{user_module}:make", length=5)
    assert env.name == "corridor" and env.spec.observation_size == 2 * 5 + 1


@pytest.mark.parametrize("path", ["corridor", "examples.corridor:", ":make", "examples/corridor:make",
                                  "examples.corridor:make:x"])
def test_a_malformed_import_path_is_one_line(path):
    with pytest.raises(ValueError, match=r"an import path must read module:factory \(e\.g\. examples\.corridor"):
        import_path.parse(path)


@pytest.mark.parametrize("factory, problem", [
    ("nosuchmodule_at_all:make", "no module named 'nosuchmodule_at_all' in "),
    ("pizero_ray.envs.nosuchmodule:make", "no module named 'pizero_ray.envs.nosuchmodule' in "),
    ("pizero_ray.envs.tsp:nosuchattr", "module pizero_ray.envs.tsp ("),
    ("{user}:value", "value must be a function returning a pizero_ray.envs.base.Environment, got int"),
    ("{user}:not_an_environment", "the factory must return a pizero_ray.envs.base.Environment, got str"),
])
def test_what_cannot_be_built_is_one_line_naming_the_environment(user_module, factory, problem):
    path = factory.format(user=user_module)
    with pytest.raises(ValueError) as raised:
        envs.make(path)
    message = str(raised.value)
    assert message.startswith(f"environment {path!r}: ") and problem in message and "\n" not in message


def test_a_missing_attribute_is_named():
    with pytest.raises(ValueError, match=r"envs/tsp\.py\) has no attribute 'nosuchattr'$"):
        envs.make("pizero_ray.envs.tsp:nosuchattr")


def test_bad_env_args_are_one_line_as_for_registered_environments(user_module):
    with pytest.raises(ValueError, match=rf"^bad parameters for environment '{user_module}:make': \{{'width': 3\}}"):
        envs.make(f"{user_module}:make", width=3)
    with pytest.raises(ValueError, match="^corridor: length must be an integer at least 2, got 1$"):
        envs.make(f"{user_module}:make", length=1)
    with pytest.raises(ValueError, match="^too long$"):  # the factory's own message, on one line
        envs.make(f"{user_module}:strict", length=10)


def test_a_module_that_fails_to_import_is_one_line(tmp_path, monkeypatch, user_module):
    (tmp_path / "broken_user_env.py").write_text("import nosuchdependency\n")
    (tmp_path / "raising_user_env.py").write_text("raise RuntimeError('no licence\\nfor this')\n")
    with pytest.raises(ValueError, match="importing broken_user_env failed: No module named 'nosuchdependency'$"):
        envs.make("broken_user_env:make")
    with pytest.raises(ValueError, match="importing raising_user_env raised RuntimeError: no licence$"):
        envs.make("raising_user_env:make")
