"""A run's files: its directory (config, metrics) and its Orbax checkpoints; loading a run to act with it."""
