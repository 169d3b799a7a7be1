import os

os.environ.setdefault("JAX_PLATFORMS", "cpu")
os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")

import pytest  # noqa: E402

from pizero_ray.config import build_config  # noqa: E402


@pytest.fixture(scope="session")
def tiny_config():
    return build_config("tiny")


@pytest.fixture(scope="session")
def tsp_env():
    import envs

    return envs.make("tsp")


@pytest.fixture(scope="session")
def compile_cache_dir(tmp_path_factory):
    """One persistent JAX cache for the session: workers after the first skip the compile."""
    return str(tmp_path_factory.mktemp("jax-cache"))


@pytest.fixture(scope="session")
def ray_session():
    """One local Ray instance per test session."""
    import ray

    ray.init(num_cpus=4, object_store_memory=128 * 1024 * 1024, include_dashboard=False, logging_level="ERROR")
    yield ray
    ray.shutdown()
