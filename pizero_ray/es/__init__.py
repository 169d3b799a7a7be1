"""OpenAI-ES: per-pair noise, fitness shaping, the update, and the population rollout.

Pure JAX and optax; imports neither Ray nor Orbax (tests/test_layers.py). The
population rollout (``es.population``) is imported on its own: it brings in
the agent.
"""

from pizero_ray.es.noise import (
    Perturbation,
    chunk_noise,
    expand_noise,
    iteration_key,
    iteration_seed,
    pair_episode_key,
    pair_noise,
    split_noise,
    weighted_noise_sum,
)
from pizero_ray.es.shaping import centered_ranks, pair_weights
from pizero_ray.es.strategy import (
    ESState,
    GradientParts,
    Strategy,
    UpdateStats,
    gradient_parts,
    make_optimizer,
    make_strategy,
)

__all__ = [
    "ESState", "GradientParts", "Perturbation", "Strategy", "UpdateStats", "centered_ranks", "chunk_noise",
    "expand_noise", "gradient_parts", "iteration_key", "iteration_seed", "make_optimizer", "make_strategy",
    "pair_episode_key", "pair_noise", "pair_weights", "split_noise", "weighted_noise_sum",
]
