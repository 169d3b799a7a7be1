"""Evaluating agents: ``runs``, a saved run's agent on fresh episodes, its plan ablation and two runs on the
same episodes; ``paired``, two agents' scores on the same episodes compared (pure NumPy/SciPy)."""
