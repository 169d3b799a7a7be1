"""Travelling salesman, swap formulation (PiZero's TSP).

``n`` cities uniform in [0, 1]^2. The tour starts as the identity order; at
step ``t`` the agent picks a city and it is swapped into position ``t``. After
``n`` steps the episode ends and the only reward, the score, is minus the
closed tour length.

With ``mask_placed`` (the default) cities already placed at positions < t are
illegal, which turns the swap formulation into tour construction; without it
any city may be swapped into position t, disturbing earlier positions.

Each candidate city's action features (what the pointer decoder scores) are,
with ``features="distances"`` (the default), its coordinates, the previous
and the first city's, its distances to those two, the progress, its placed
flag and whether a city is placed yet: the distance to the previous city
hands the decoder the nearest-neighbour answer. ``features="paper"`` gives
only each city's own coordinates and its placed flag, so that whatever the
agent knows of distances it must work out (the paper's observation is the
flat coordinates plus the timestep, which ``vector`` is in both modes).

Also here: exact Held-Karp (n <= 12) and nearest-neighbour reference solvers in
NumPy, used by evaluations to report the gap to optimal.
"""

from __future__ import annotations

from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from pizero_ray.envs.base import Environment, EnvSpec, Observation, require_bool, require_choice, require_int

MAX_EXACT_CITIES = 12
FEATURES = ("distances", "paper")
ACTION_FEATURE_SIZES = {"distances": 11, "paper": 3}


class TSPState(NamedTuple):
    coordinates: jax.Array  # [n, 2] in the cities' original index order
    tour: jax.Array  # [n] int32: tour[p] is the city at position p
    t: jax.Array  # int32: the position filled next


def tour_length(coordinates: jax.Array, tour: jax.Array) -> jax.Array:
    """Closed tour length; works on batches through vmap."""
    ordered = coordinates[tour]
    return jnp.sum(jnp.linalg.norm(ordered - jnp.roll(ordered, -1, axis=0), axis=-1))


def distance_features(state: TSPState, placed: jax.Array) -> jax.Array:
    """Per city [n, 11]: coordinates, the previous and first city's, distances to them, progress, placed, started."""
    n = state.tour.shape[0]
    has_prev = state.t > 0
    prev = jnp.where(has_prev, state.coordinates[state.tour[jnp.maximum(state.t - 1, 0)]], 0.0)
    first = jnp.where(has_prev, state.coordinates[state.tour[0]], 0.0)
    to_prev = jnp.where(has_prev, jnp.linalg.norm(state.coordinates - prev, axis=-1), 0.0)
    to_first = jnp.where(has_prev, jnp.linalg.norm(state.coordinates - first, axis=-1), 0.0)
    progress = state.t.astype(jnp.float32) / n
    return jnp.concatenate(
        [
            state.coordinates,
            jnp.broadcast_to(prev, (n, 2)),
            jnp.broadcast_to(first, (n, 2)),
            to_prev[:, None],
            to_first[:, None],
            jnp.full((n, 1), progress),
            placed[:, None].astype(jnp.float32),
            jnp.full((n, 1), has_prev.astype(jnp.float32)),
        ],
        axis=-1,
    )


def make(num_cities: int = 10, mask_placed: bool = True, features: str = "distances") -> Environment:
    require_int("tsp", "num_cities", num_cities, 3)
    require_bool("tsp", "mask_placed", mask_placed)
    require_choice("tsp", "features", features, FEATURES)
    n = num_cities

    def observe(state: TSPState) -> Observation:
        position_of = jnp.argsort(state.tour)  # city -> its position in the tour
        placed = position_of < state.t
        if features == "paper":
            candidates = jnp.concatenate([state.coordinates, placed[:, None].astype(jnp.float32)], axis=-1)
        else:
            candidates = distance_features(state, placed)
        vector = jnp.concatenate(
            [state.coordinates[state.tour].reshape(-1), jax.nn.one_hot(state.t, n)]
        )
        mask = ~placed if mask_placed else jnp.ones((n,), dtype=bool)
        return Observation(vector, candidates, mask)

    def reset(key: jax.Array) -> tuple[TSPState, Observation]:
        coordinates = jax.random.uniform(key, (n, 2), dtype=jnp.float32)
        state = TSPState(coordinates, jnp.arange(n, dtype=jnp.int32), jnp.int32(0))
        return state, observe(state)

    def step(state: TSPState, action: jax.Array):
        city = action.astype(jnp.int32)
        position = jnp.argmax(state.tour == city)
        tour = state.tour.at[position].set(state.tour[state.t]).at[state.t].set(city)
        state = TSPState(state.coordinates, tour, state.t + 1)
        done = state.t >= n
        reward = jnp.where(done, -tour_length(state.coordinates, tour), 0.0)
        return state, observe(state), reward, done

    spec = EnvSpec(
        observation_size=3 * n,
        horizon=n,
        num_actions=n,
        action_feature_size=ACTION_FEATURE_SIZES[features],
    )
    return Environment("tsp", spec, reset, step, render=render, references=references)


def references(initial_states: TSPState, scores: np.ndarray) -> dict[str, float]:
    """The agent's tours next to nearest neighbour and, for n <= 12, the exact optimum."""
    coordinates = np.asarray(initial_states.coordinates, dtype=np.float64)
    tours = -np.asarray(scores, dtype=np.float64)
    nearest = float(nearest_neighbour_tour_length(coordinates).mean())
    # *_score: the same in the agent's units (minus the tour length), for plots beside its scores.
    out = {
        "mean_tour_length": float(tours.mean()),
        "nearest_neighbour_tour_length": nearest,
        "nearest_neighbour_score": -nearest,
        "random_score": -float(random_tour_length(coordinates).mean()),
    }
    if coordinates.shape[1] <= MAX_EXACT_CITIES:
        optimal = optimal_tour_length(coordinates)
        out["optimal_tour_length"] = float(optimal.mean())
        out["optimal_score"] = -out["optimal_tour_length"]
        out["ratio_to_optimal"] = float(tours.mean() / optimal.mean())
        out["mean_optimality_gap"] = float((tours / optimal - 1.0).mean())
    return out


# ---------------------------------------------------------------- rendering

RENDER_SIZE = 560
TOUR_COLOUR = (40, 90, 200)
CITY_COLOUR = (30, 30, 30)  # the edge of every city and the fill of the first
CURRENT_COLOUR = (220, 60, 40)
BORDER_COLOUR = (210, 210, 210)


def placed_path_length(state: TSPState) -> float:
    """Length of the tour placed so far: the open path through positions < t, closed once all are placed."""
    coordinates = np.asarray(state.coordinates, dtype=np.float64)
    tour, t = np.asarray(state.tour), int(state.t)
    path = coordinates[tour[:t]]
    if t == len(tour):
        path = np.concatenate([path, path[:1]])
    return float(np.linalg.norm(np.diff(path, axis=0), axis=-1).sum())


def render(state: TSPState, size: int = RENDER_SIZE) -> np.ndarray:
    """As the paper draws a tour: the first city filled, the others hollow, the tour so far as lines.

    The tour closes once complete; mid-episode a ring marks the city placed last.
    """
    from PIL import Image, ImageDraw

    margin, radius, width = size // 20, max(3, size // 70), max(2, size // 160)
    coordinates = np.asarray(state.coordinates)
    tour = np.asarray(state.tour)
    t, n = int(state.t), len(tour)
    to_pixels = lambda xy: (margin + xy[0] * (size - 2 * margin), size - margin - xy[1] * (size - 2 * margin))
    image = Image.new("RGB", (size, size), "white")
    draw = ImageDraw.Draw(image)
    draw.rectangle((margin, margin, size - margin, size - margin), outline=BORDER_COLOUR)
    path = [to_pixels(coordinates[city]) for city in tour[:t]]
    if t == n:
        path.append(path[0])
    if len(path) > 1:
        draw.line(path, fill=TOUR_COLOUR, width=width, joint="curve")
    for city, xy in enumerate(coordinates):
        x, y = to_pixels(xy)
        first = t > 0 and city == tour[0]
        draw.ellipse((x - radius, y - radius, x + radius, y + radius), fill=CITY_COLOUR if first else "white",
                     outline=CITY_COLOUR, width=width)
    if 0 < t < n:
        x, y, ring = *to_pixels(coordinates[tour[t - 1]]), 2 * radius
        draw.ellipse((x - ring, y - ring, x + ring, y + ring), outline=CURRENT_COLOUR, width=width)
    return np.asarray(image)


# ---------------------------------------------------------------- reference solvers


def _distances(coordinates: np.ndarray) -> np.ndarray:
    diff = coordinates[..., :, None, :] - coordinates[..., None, :, :]
    return np.sqrt((diff**2).sum(-1))


def optimal_tour_length(coordinates: np.ndarray) -> np.ndarray:
    """Exact shortest closed tour by Held-Karp dynamic programming.

    ``coordinates``: [n, 2] or a batch [B, n, 2] with n <= 12. Vectorised over
    the batch, so a thousand TSP10 instances take a few seconds.
    """
    coordinates = np.asarray(coordinates, dtype=np.float64)
    single = coordinates.ndim == 2
    batch = coordinates[None] if single else coordinates
    b, n, _ = batch.shape
    if not 2 <= n <= MAX_EXACT_CITIES:
        raise ValueError(f"Held-Karp handles 2..{MAX_EXACT_CITIES} cities, got {n}")
    d = _distances(batch)
    m = n - 1  # city 0 is the fixed start; subsets range over cities 1..n-1
    cost = np.full((b, 1 << m, m), np.inf)
    cost[:, 1 << np.arange(m), np.arange(m)] = d[:, 0, 1:]
    for subset in range(1, 1 << m):
        members = [j for j in range(m) if subset >> j & 1]
        if len(members) < 2:
            continue
        for k in members:
            previous = subset & ~(1 << k)
            others = [j for j in members if j != k]
            cost[:, subset, k] = np.min(cost[:, previous, others] + d[:, 1 + np.array(others), 1 + k], axis=1)
    best = np.min(cost[:, (1 << m) - 1, :] + d[:, 1:, 0], axis=1)
    return best[0] if single else best


def random_tour_length(coordinates: np.ndarray, seed: int = 0) -> np.ndarray:
    """The length of a uniformly random tour of each instance (a fixed seed); [B,n,2] -> [B]."""
    coordinates = np.asarray(coordinates, dtype=np.float64)
    rng = np.random.default_rng(seed)
    order = np.argsort(rng.random(coordinates.shape[:2]), axis=1)
    tours = np.take_along_axis(coordinates, order[..., None], axis=1)
    return np.linalg.norm(tours - np.roll(tours, -1, axis=1), axis=-1).sum(axis=1)


def nearest_neighbour_tour_length(coordinates: np.ndarray, start: int = 0) -> np.ndarray:
    """Greedy nearest-neighbour tour from a fixed start city; [n,2] or [B,n,2]."""
    coordinates = np.asarray(coordinates, dtype=np.float64)
    single = coordinates.ndim == 2
    batch = coordinates[None] if single else coordinates
    b, n, _ = batch.shape
    d = _distances(batch)
    rows = np.arange(b)
    visited = np.zeros((b, n), dtype=bool)
    current = np.full(b, start)
    visited[rows, current] = True
    total = np.zeros(b)
    for _ in range(n - 1):
        candidate = np.where(visited, np.inf, d[rows, current])
        nxt = candidate.argmin(axis=1)
        total += candidate[rows, nxt]
        visited[rows, nxt] = True
        current = nxt
    total += d[rows, current, start]
    return total[0] if single else total
