"""Environments of your own, written against the protocol (pizero_ray.envs.base) and named by import path: user code,
not registered in ``pizero_ray.envs``. docs/your-environment.md walks through ``examples/corridor.py``."""
