"""Facility location with continuous actions (PiZero's FLP).

``num_clients`` clients lie uniform in [0, 1]^2. At each of ``num_facilities``
steps the agent outputs a point in [0, 1]^2 (clipped into it) and a facility
is placed there. After the last one the episode ends and the only reward, the
score, is minus the clients' cost: with objective ``max`` (the continuous
k-center problem, env ``flp``) the largest distance from a client to its
nearest facility, the covering radius; with ``mean`` (continuous k-median,
env ``flp-mean``) the mean of those distances.

Observation vector, by ``view``, then the facilities placed so far
(zero-padded to ``m``), one placed flag per facility slot and the timestep as
a fraction t / m:

* ``"flat"`` (``2 n + 3 m + 1`` floats): the client coordinates, flattened.
  An MLP over them must learn the same rule once for every client slot, and
  the same instance reads differently under every order of its clients.
* ``"grid"`` (``2 g^2 + 3 m + 1`` floats, g = ``grid_size``): the unit square
  cut into g x g cells, as two planes: the share of the clients in each cell,
  and the share of the cost they pay so far (each client's distance to its
  nearest placed facility, sqrt(2), the diagonal, while none is placed,
  summed per cell and divided by n sqrt(2)). Both are functions of the
  clients as a set. The second is what the reward will add up; it does not
  say where to place a facility.

There are no discrete
actions: ``action_features`` is [0, 0] and ``action_mask`` is empty.
``pizero eval`` also reports both objectives of the agent's placements
(``mean_covering_radius``, ``mean_mean_distance``), whichever it trains on.

References, in JAX on the same instances as the agent, each placement scored
with the environment's objective:

* ``farthest_first_score``: Gonzalez's farthest-first traversal, the classic
  2-approximation of the max objective (its radius is at most twice the
  optimum, wherever the optimum's facilities lie). It starts from the client
  nearest the clients' centroid rather than from client 0, a random client
  since clients are i.i.d.; that is deterministic and a better first centre
  (-0.499 against -0.531 from client 0, max objective).
* ``kmeans_score``: ``LLOYD_ITERATIONS`` Lloyd (k-means) iterations seeded from
  farthest-first: assign each client to its nearest facility, move each
  facility to its clients' centroid.
* ``lloyd_score``: as many further Lloyd iterations from the k-means result
  whose update suits the objective: each facility moves to (near) the centre
  of its clients' smallest enclosing circle for max (Badoiu-Clarkson), to
  their geometric median for mean (Weiszfeld). The strongest reference here.
* ``random_score``: uniform random points (fixed key).

Measured over the 1,000 instances ``pizero eval --episodes 1000 --seed 0``
plays (default parameters)::

    objective  farthest-first  k-means  Lloyd   random
    max            -0.499      -0.403   -0.348  -0.645
    mean           -0.247      -0.201   -0.194  -0.322

with (``flp-mean`` for the second row)::

    JAX_PLATFORMS=cpu python -c "import jax, numpy as np, envs; from pizero_ray.agent.episodes import \\
      episode_reset_keys as k; env = envs.make('flp'); s, _ = jax.vmap(env.reset)(k(jax.random.PRNGKey(0), \\
      1000)); print(env.references(s, np.zeros(1000)))"

Gonzalez's guarantee is loose in practice: on uniform instances it places
facilities on extreme clients and is beaten by plain k-means even on the max
objective.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from pizero_ray.envs.base import Environment, EnvSpec, Observation, require_choice, require_int

OBJECTIVES = ("max", "mean")
VIEWS = ("flat", "grid")
LLOYD_ITERATIONS = 10
CENTRE_ITERATIONS = 100  # Weiszfeld or Badoiu-Clarkson steps per Lloyd update
RANDOM_PLACEMENT_SEED = 0

class FLPState(NamedTuple):
    clients: jax.Array  # [n, 2]
    facilities: jax.Array  # [m, 2]: the first t are placed, the rest are zeros
    t: jax.Array  # int32: facilities placed so far


def nearest_facility_distances(clients: jax.Array, facilities: jax.Array, placed: jax.Array) -> jax.Array:
    """[n] distance from each client to its nearest placed facility (inf while none is placed)."""
    distances = jnp.linalg.norm(clients[:, None, :] - facilities[None, :, :], axis=-1)
    return jnp.min(jnp.where(placed[None, :], distances, jnp.inf), axis=1)


def cost(clients: jax.Array, facilities: jax.Array, objective: str) -> jax.Array:
    """The objective with every facility placed: covering radius (max) or mean distance (mean)."""
    distances = nearest_facility_distances(clients, facilities, jnp.ones(facilities.shape[0], bool))
    return jnp.max(distances) if objective == "max" else jnp.mean(distances)




def client_grid(state: FLPState, grid_size: int) -> jax.Array:
    """The clients as two [g, g] planes, flattened: their share per cell, and the share of the cost they pay."""
    n = state.clients.shape[0]
    cells = jnp.clip(jnp.floor(state.clients * grid_size).astype(jnp.int32), 0, grid_size - 1)
    # One-hot rows and a product rather than a scatter-add: half the time on CPU, vmapped over a population.
    in_cell = jax.nn.one_hot(cells[:, 0] * grid_size + cells[:, 1], grid_size * grid_size)  # [n, g^2]
    placed = jnp.arange(state.facilities.shape[0]) < state.t
    diagonal = jnp.sqrt(2.0)
    paid = jnp.minimum(nearest_facility_distances(state.clients, state.facilities, placed), diagonal)
    return jnp.concatenate([in_cell.sum(0) / n, paid @ in_cell / (n * diagonal)]).astype(jnp.float32)


def make(num_clients: int = 20, num_facilities: int = 3, objective: str = "max", view: str = "flat",
         grid_size: int = 8) -> Environment:
    require_choice("flp", "objective", objective, OBJECTIVES)
    name = "flp" if objective == "max" else f"flp-{objective}"
    require_int(name, "num_clients", num_clients, 1)
    require_int(name, "num_facilities", num_facilities, 1, num_clients)
    require_choice(name, "view", view, VIEWS)
    require_int(name, "grid_size", grid_size, 1)
    n, m = num_clients, num_facilities
    clients_size = 2 * grid_size * grid_size if view == "grid" else 2 * n

    def observe_clients(state: FLPState) -> jax.Array:
        return client_grid(state, grid_size) if view == "grid" else state.clients.reshape(-1)

    def observe(state: FLPState) -> Observation:
        placed = jnp.arange(m) < state.t
        vector = jnp.concatenate([
            observe_clients(state),
            state.facilities.reshape(-1),
            placed.astype(jnp.float32),
            (state.t / m).astype(jnp.float32)[None],
        ])
        return Observation(vector, jnp.zeros((0, 0), jnp.float32), jnp.zeros((0,), bool))

    def reset(key: jax.Array) -> tuple[FLPState, Observation]:
        clients = jax.random.uniform(key, (n, 2), dtype=jnp.float32)
        state = FLPState(clients, jnp.zeros((m, 2), jnp.float32), jnp.int32(0))
        return state, observe(state)

    def step(state: FLPState, action: jax.Array):
        facility = jnp.clip(action.astype(jnp.float32), 0.0, 1.0)
        state = FLPState(state.clients, state.facilities.at[state.t].set(facility), state.t + 1)
        done = state.t >= m
        reward = jnp.where(done, -cost(state.clients, state.facilities, objective), 0.0)
        return state, observe(state), reward, done

    spec = EnvSpec(
        observation_size=clients_size + 3 * m + 1,
        horizon=m,
        num_actions=0,
        action_feature_size=0,
        action_dim=2,
        action_low=0.0,
        action_high=1.0,
    )
    return Environment(
        name, spec, reset, step,
        render=functools.partial(render, objective=objective),
        references=functools.partial(references, objective=objective),
        episode_metrics=episode_metrics,
    )


def episode_metrics(final_states: FLPState) -> dict[str, np.ndarray]:
    """Both objectives of the agent's placements [E], whichever one it was trained on."""
    both = jax.vmap(lambda c, f: jnp.stack([cost(c, f, "max"), cost(c, f, "mean")]))
    values = np.asarray(both(jnp.asarray(final_states.clients), jnp.asarray(final_states.facilities)))
    return {"covering_radius": values[:, 0], "mean_distance": values[:, 1]}


# ---------------------------------------------------------------- reference placements


def farthest_first(clients: jax.Array, num_facilities: int) -> jax.Array:
    """Gonzalez's traversal [m, 2]: start at the client nearest the centroid, then always the farthest client."""
    start = jnp.argmin(jnp.linalg.norm(clients - clients.mean(axis=0), axis=-1))
    facilities = jnp.zeros((num_facilities, 2), clients.dtype).at[0].set(clients[start])

    def add(i, facilities):
        placed = jnp.arange(num_facilities) < i
        farthest = jnp.argmax(nearest_facility_distances(clients, facilities, placed))
        return facilities.at[i].set(clients[farthest])

    return jax.lax.fori_loop(1, num_facilities, add, facilities)


def centroid(clients: jax.Array, members: jax.Array) -> jax.Array:
    """Mean of the member clients ([n] 0/1 weights): the point minimising their squared distances."""
    return members @ clients / jnp.maximum(members.sum(), 1.0)


def geometric_median(clients: jax.Array, members: jax.Array, iterations: int = CENTRE_ITERATIONS) -> jax.Array:
    """Weiszfeld's iterations from the centroid: the point minimising the members' mean distance.

    The small floor on distances keeps a point sitting on a client from dividing by zero.
    """

    def weiszfeld(_, point):
        weights = members / jnp.maximum(jnp.linalg.norm(clients - point, axis=-1), 1e-9)
        return weights @ clients / jnp.maximum(weights.sum(), 1e-30)

    return jax.lax.fori_loop(0, iterations, weiszfeld, centroid(clients, members))


def enclosing_centre(clients: jax.Array, members: jax.Array, iterations: int = CENTRE_ITERATIONS) -> jax.Array:
    """Badoiu-Clarkson iterations from the centroid: near the centre of the members' smallest enclosing circle.

    Each step moves 1/(i+2) of the way to the farthest member; after T steps
    the radius is within a factor 1 + O(1/sqrt(T)) of the smallest.
    """

    def towards_farthest(i, point):
        distances = jnp.where(members > 0, jnp.linalg.norm(clients - point, axis=-1), -1.0)
        return point + (clients[jnp.argmax(distances)] - point) / (i + 2)

    return jax.lax.fori_loop(0, iterations, towards_farthest, centroid(clients, members))


def lloyd(clients: jax.Array, facilities: jax.Array, centre_of, iterations: int = LLOYD_ITERATIONS) -> jax.Array:
    """Lloyd's alternation: assign every client to its nearest facility, move each facility to
    ``centre_of(clients, members)`` of its clients; a facility without clients stays put."""
    m = facilities.shape[0]

    def iterate(_, facilities):
        distances = jnp.linalg.norm(clients[:, None, :] - facilities[None, :, :], axis=-1)  # [n, m]
        members = jax.nn.one_hot(jnp.argmin(distances, axis=1), m).T  # [m, n]
        moved = jax.vmap(centre_of, in_axes=(None, 0))(clients, members)
        return jnp.where((members.sum(axis=1) > 0)[:, None], moved, facilities)

    return jax.lax.fori_loop(0, iterations, iterate, facilities)


def reference_placements(clients: jax.Array, num_facilities: int, objective: str) -> dict[str, jax.Array]:
    """Facilities [E, m, 2] of each reference on a batch of instances [E, n, 2]."""
    episodes = clients.shape[0]
    greedy = jax.vmap(farthest_first, in_axes=(0, None))(clients, num_facilities)
    kmeans = jax.vmap(lambda c, f: lloyd(c, f, centroid))(clients, greedy)
    centre_of = enclosing_centre if objective == "max" else geometric_median
    key = jax.random.PRNGKey(RANDOM_PLACEMENT_SEED)
    return {
        "farthest_first": greedy,
        "kmeans": kmeans,
        "lloyd": jax.vmap(lambda c, f: lloyd(c, f, centre_of))(clients, kmeans),
        "random": jax.random.uniform(key, (episodes, num_facilities, 2), dtype=clients.dtype),
    }


def references(initial_states: FLPState, scores: np.ndarray, *, objective: str) -> dict[str, float]:
    """Mean scores of farthest-first, Lloyd and random placements on the agent's instances."""
    clients = jnp.asarray(initial_states.clients)
    placements = jax.jit(reference_placements, static_argnums=(1, 2))(clients, initial_states.facilities.shape[1],
                                                                       objective)
    score_of = jax.jit(jax.vmap(lambda c, f: -cost(c, f, objective)))
    return {f"{name}_score": float(jnp.mean(score_of(clients, facilities))) for name, facilities in placements.items()}


# ---------------------------------------------------------------- rendering

SIZE = 560
MARGIN = 28
CLIENT_COLOUR = (90, 90, 90)
FACILITY_COLOUR = (220, 60, 40)
LINK_COLOUR = (120, 160, 225)
RADIUS_COLOUR = (240, 150, 130)


def render(state: FLPState, objective: str = "max") -> np.ndarray:
    """As the paper draws a placement: clients as dots, facilities as squares, a line from each
    client to its assigned (nearest) facility.

    For max, also the covering radius: a circle of that radius around every
    facility, and the link of the client that sets it.
    """
    from PIL import Image, ImageDraw

    clients = np.asarray(state.clients, dtype=np.float64)
    facilities = np.asarray(state.facilities, dtype=np.float64)
    placed = facilities[:int(state.t)]
    scale = SIZE - 2 * MARGIN
    to_pixels = lambda xy: (MARGIN + xy[0] * scale, SIZE - MARGIN - xy[1] * scale)
    image = Image.new("RGB", (SIZE, SIZE), "white")
    draw = ImageDraw.Draw(image)
    draw.rectangle((MARGIN, MARGIN, SIZE - MARGIN, SIZE - MARGIN), outline=(210, 210, 210))
    if len(placed):
        distances = np.linalg.norm(clients[:, None] - placed[None], axis=-1)
        nearest = distances.argmin(axis=1)
        for client, facility in zip(clients, nearest):
            draw.line([to_pixels(client), to_pixels(placed[facility])], fill=LINK_COLOUR, width=2)
        if objective == "max":
            critical = distances.min(axis=1).argmax()  # the client that sets the radius
            draw.line([to_pixels(clients[critical]), to_pixels(placed[nearest[critical]])], fill=RADIUS_COLOUR,
                      width=3)
            radius = distances.min(axis=1).max() * scale
            for facility in placed:
                x, y = to_pixels(facility)
                draw.ellipse((x - radius, y - radius, x + radius, y + radius), outline=RADIUS_COLOUR, width=2)
    for client in clients:
        x, y = to_pixels(client)
        draw.ellipse((x - 5, y - 5, x + 5, y + 5), fill=CLIENT_COLOUR)
    for facility in placed:
        x, y = to_pixels(facility)
        draw.rectangle((x - 9, y - 9, x + 9, y + 9), fill=FACILITY_COLOUR)
    return np.asarray(image)
