"""The agent's math: networks, the planner over the learned abstract model, the decoder, episodes.

Pure JAX over parameter pytrees; imports neither Ray nor Orbax (tests/test_layers.py).
"""

from pizero_ray.agent.pizero import PLAN_ABLATIONS, Agent, StepInfo, ablate_plan, make_agent, without_memory

__all__ = ["PLAN_ABLATIONS", "Agent", "StepInfo", "ablate_plan", "make_agent", "without_memory"]
