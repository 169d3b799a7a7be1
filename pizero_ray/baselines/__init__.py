"""The gradient-trained baselines: AlphaZero (search over the true simulator) and MuZero (over a learned model).

Pure JAX over parameter pytrees, as the agent is; imports neither Ray nor
Orbax (tests/test_layers.py). ``make_learner(config, env)`` is the whole
method: self-play, the replay buffer, the losses and Adam, one jitted
iteration. The trainer's loop, checkpoints and metrics are the ES runs'.
"""

from pizero_ray.baselines.learner import Learner, LearnerState, LearnerStats, make_learner

__all__ = ["Learner", "LearnerState", "LearnerStats", "make_learner"]
