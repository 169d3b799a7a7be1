"""The agent's math: networks, the planner over the learned abstract model, the decoder, episodes.

Pure JAX over parameter pytrees; imports neither Ray nor Orbax (tests/test_layers.py).
"""

from pizero_ray.agent.pizero import Agent, StepInfo, make_agent, without_memory

__all__ = ["Agent", "StepInfo", "make_agent", "without_memory"]
