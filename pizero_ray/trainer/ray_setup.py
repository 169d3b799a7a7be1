"""Connecting to Ray: a cluster at an address, or an embedded local instance."""

from __future__ import annotations

import os
import warnings

# Small enough for a 2-core CI box; only parameters (KBs to MBs) live there.
LOCAL_OBJECT_STORE_BYTES = 256 * 1024 * 1024


def init(address: str | None = None, num_cpus: int | None = None) -> str:
    """Joins ``address`` (or RAY_ADDRESS); with neither, starts a local instance.

    Returns a short description of what it connected to. A Ray instance that is
    already initialised in this process (tests, a notebook) is reused.
    """
    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")  # no phoning home, and no network here
    import ray

    if ray.is_initialized():
        return "existing Ray connection"
    address = address or os.environ.get("RAY_ADDRESS") or None
    if address:
        # Token authentication (on by default since Ray 2.59) reads RAY_AUTH_TOKEN
        # or ~/.ray/auth_token; see cluster/README.md.
        ray.init(address=address, log_to_driver=True, logging_level="WARNING")
        return f"Ray cluster at {address}"
    with warnings.catch_warnings():
        # JAX warns at any fork once its threads run (an experiment has built its environments by now); Ray's
        # fork is subprocess's fork-and-exec of its own binaries, which runs no JAX code in the child.
        warnings.filterwarnings("ignore", message=r"os\.fork\(\) was called", category=RuntimeWarning)
        _init_local(num_cpus)
    return "local Ray instance"


def _init_local(num_cpus: int | None) -> None:
    import ray

    ray.init(
        address="local",  # a new instance even if another Ray runs on this machine: join one only when asked
        num_cpus=num_cpus or os.cpu_count(),
        object_store_memory=LOCAL_OBJECT_STORE_BYTES,
        include_dashboard=False,
        logging_level="WARNING",
    )
