"""What evaluations tell apart: ``paired``, two agents' scores on the same episodes (pure NumPy/SciPy)."""
