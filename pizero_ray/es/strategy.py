"""OpenAI-ES as a strategy over an explicit state: ``init``, ``ask``, ``tell`` (``make_strategy``).

The pseudo-gradient
    g = sum_i w_i z_i / (2 sigma n),   w_i = shaped(score_i+) - shaped(score_i-)
is a sum of per-chunk parts (``GradientParts``), added in chunk order: where
parts are formed on the workers (``--gradient-on``), the worker that evaluated
a chunk computes its part from the noise it kept; the driver regenerates the
noise of any other chunk, or of every chunk when it forms them all (one chunk
in memory at a time).
Then Adam takes an ascent step. The state (``ESState``: flat parameters,
optax state, iteration) is explicit; the strategy's functions are bound to the
config once.
"""

from __future__ import annotations

import functools
from typing import Callable, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
import optax

from pizero_ray.config import Config
from pizero_ray.es.noise import Perturbation, chunk_noise, iteration_key, iteration_seed, weighted_noise_sum
from pizero_ray.es.shaping import pair_weights


class GradientParts(NamedTuple):
    """The pseudo-gradient chunk by chunk: each chunk's share sum_{i in chunk} w_i z_i, wherever it is computed.

    A worker computes a chunk's part from the noise it kept from evaluating the
    chunk, anyone else from regenerated noise: both go through the same
    ``part`` function on the same noise, so the part is the same bits either
    way, and ``total`` adds the parts in chunk order.
    """

    noise: Callable[[np.uint32, np.int32], jax.Array]  # jitted: (iteration seed, first pair) -> noise [C, noise_size]
    part: Callable[[np.ndarray, jax.Array], jax.Array]  # jitted: (weights [C], noise [C, noise_size]) -> [D]
    chunk_size: int
    parameter_size: int
    # jitted: (weights [n, C], noise [n, C, noise_size]) -> the n chunks' parts [n, D] in one program, each the
    # bits ``part`` gives it (low-rank noise only: a batch of full-rank products may round otherwise)
    many: Callable[[np.ndarray, jax.Array], jax.Array] | None = None

    def from_noise(self, weights: np.ndarray, noise) -> np.ndarray:
        """The part of a chunk whose noise is at hand (kept from its evaluation, or regenerated)."""
        return np.asarray(self.part(np.asarray(weights, np.float32), noise), np.float32)

    def regenerated(self, seed, first_pair: int, weights: np.ndarray) -> np.ndarray:
        return self.from_noise(weights, self.noise(np.uint32(seed), np.int32(first_pair)))

    def chunk_here(self, seed, weights: np.ndarray, chunk_index: int) -> np.ndarray:
        """Chunk ``chunk_index``'s part from regenerated noise; zeros for a chunk whose weights are all zero."""
        chunk_weights = weights[chunk_index * self.chunk_size:(chunk_index + 1) * self.chunk_size]
        if not chunk_weights.any():
            return np.zeros(self.parameter_size, np.float32)
        return self.regenerated(seed, chunk_index * self.chunk_size, chunk_weights)

    @staticmethod
    def total(parts) -> np.ndarray:
        """sum of the parts, added one by one in the given (chunk) order."""
        total = None
        for part in parts:
            total = np.array(part, np.float32) if total is None else total + part
        return total


def gradient_parts(config: Config, perturbation: Perturbation) -> GradientParts:
    noise_size, chunk = perturbation.noise_size, config.chunk_size

    def noise(seed, first_pair):
        return chunk_noise(iteration_key(seed), first_pair, chunk, noise_size)

    def part(weights, noise):
        return weighted_noise_sum(weights, noise, perturbation)

    def many(weights, noise):  # one loop over the rows for every matrix of every chunk: fewer launches on a GPU
        return jax.vmap(functools.partial(weighted_noise_sum, perturbation=perturbation, one_loop=True))(
            weights, noise)

    return GradientParts(jax.jit(noise), jax.jit(part), chunk, perturbation.parameter_size,
                         jax.jit(many) if perturbation.rank > 0 else None)


def learning_rate(config: Config) -> float | optax.Schedule:
    """Adam's step size: the constant --lr, or its cosine decay to 0 over --lr-decay-iterations."""
    if config.lr_decay_iterations == 0:
        return config.learning_rate  # no schedule state: checkpoints of constant-lr runs keep their layout
    return optax.cosine_decay_schedule(config.learning_rate, config.lr_decay_iterations)


def make_optimizer(config: Config) -> optax.GradientTransformation:
    # optax minimises: it is handed -g. Decoupled-from-nothing L2 decay is
    # added to that loss gradient, as OpenAI-ES's l2 coefficient does.
    return optax.chain(optax.add_decayed_weights(config.weight_decay), optax.adam(learning_rate(config)))


class ESState(NamedTuple):
    """Everything OpenAI-ES carries from one iteration to the next."""

    theta: jax.Array  # flat parameters [D]
    opt_state: optax.OptState
    iteration: int  # iterations done; the next one's seed is a function of it

    @property
    def carried(self) -> optax.OptState:
        """What training continues from besides theta and the iteration (what a checkpoint keeps of it)."""
        return self.opt_state

    def with_carried(self, carried: optax.OptState) -> ESState:
        return self._replace(opt_state=carried)


class UpdateStats(NamedTuple):
    """What one ``tell`` saw and did: the scores that came in, and the step's sizes."""

    mean_score: float
    std_score: float
    max_score: float
    min_score: float
    pairs: int  # pairs whose scores came in
    non_finite_scores: int  # members among them whose score was NaN or infinite (they rank last: es.shaping)
    gradient_norm: float
    update_norm: float
    parameter_norm: float


class Strategy(NamedTuple):
    """OpenAI-ES bound to a config, as evosax's strategies: ``init``, ``ask``, ``tell`` over an explicit state.

    Between ``ask`` and ``tell`` the caller scores the population and gathers
    the chunks' gradient parts (``parts``), wherever they are computed; it
    needs the pair weights for that (``weights``).
    """

    init: Callable[[jax.Array], ESState]  # initial flat parameters -> state
    ask: Callable[[ESState], int]  # -> the iteration seed the population is drawn from
    weights: Callable[[np.ndarray, np.ndarray], np.ndarray]  # (scores [n, 2], valid [n]) -> pair weights [n]
    tell: Callable[[ESState, np.ndarray, np.ndarray, list], tuple[ESState, UpdateStats]]
    parts: GradientParts


def make_strategy(config: Config, perturbation: Perturbation) -> Strategy:
    """OpenAI-ES with ``config``'s shaping, sigma and optimiser over parameters laid out as ``perturbation``."""
    optimizer = make_optimizer(config)
    parts = gradient_parts(config, perturbation)

    def init(theta) -> ESState:
        theta = jnp.asarray(theta, jnp.float32)
        return ESState(theta, optimizer.init(theta), 0)

    def ask(state: ESState) -> int:
        return iteration_seed(config.seed, state.iteration)

    shaped = jax.jit(functools.partial(pair_weights, fitness_shaping=config.fitness_shaping))

    @jax.jit
    def step(theta, opt_state, parts_total, num_pairs):
        g = parts_total / (2.0 * config.sigma * num_pairs.astype(jnp.float32))
        updates, opt_state = optimizer.update(-g, opt_state, theta)
        new_theta = optax.apply_updates(theta, updates)
        return new_theta, opt_state, (jnp.linalg.norm(g), jnp.linalg.norm(updates), jnp.linalg.norm(new_theta))

    def weights(scores, valid) -> np.ndarray:
        return np.asarray(shaped(jnp.asarray(scores), valid=jnp.asarray(valid)))

    def tell(state: ESState, scores, valid, chunk_parts) -> tuple[ESState, UpdateStats]:
        """The Adam step on sum(parts) / (2 sigma n), n the pairs that came in; ``chunk_parts`` in chunk order."""
        valid = np.asarray(valid, bool)
        num_pairs = jnp.maximum(jnp.sum(jnp.asarray(valid)), 1)
        theta, opt_state, norms = step(state.theta, state.opt_state, GradientParts.total(chunk_parts), num_pairs)
        came_in = np.asarray(scores)[valid]
        finite = came_in[np.isfinite(came_in)]  # the broken ones are counted, not averaged (es.shaping)
        summary = finite if finite.size else np.full(1, np.nan, np.float32)
        stats = UpdateStats(float(summary.mean()), float(summary.std()), float(summary.max()), float(summary.min()),
                            int(valid.sum()), int(came_in.size - finite.size), *(float(norm) for norm in norms))
        return ESState(theta, opt_state, state.iteration + 1), stats

    return Strategy(init, ask, weights, tell, parts)
