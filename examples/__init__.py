"""Environments of your own, written against the protocol (envs.base) and named by import path: user code,
not registered in ``envs``. docs/your-environment.md walks through ``examples/corridor.py``."""
