"""Collect: walk a small walled grid and pick up coins (PiZero's micro/macro showcase).

An 8x8 grid (``size``) with walls on its border, so the walkable interior is
6x6. At reset the agent and ``num_coins`` coins are placed uniformly at random
on distinct interior cells. Actions are the four moves (0 up, 1 right, 2 down,
3 left); moving into a wall leaves the agent in place. A coin is collected when
the agent enters its cell. After ``horizon`` steps (20) the episode ends and
the score is minus the number of coins left.

The interesting part is the gap between the micro-actions the environment
takes (single moves) and the macro-actions that matter ("go to that coin
next"): planning over an abstract model can work at the level of the latter.

Rewards: the whole score comes at the final step, ``-(coins left)``, and
every other step pays 0, as in TSP. (Paying +1 per coin and ``-num_coins`` at
the end sums to the same score but is only right for states that started with
``num_coins`` coins; ES sees nothing but the sum either way.)

Default ``num_coins = 12`` (a third of the interior): twenty moves are often
not enough for all of them, and the order of visits matters. The greedy
nearest-coin walker leaves about 1.0 coins on average where the best walk
leaves 0.4; with 8 coins both collect nearly everything (-0.12 and -0.01),
so there would be little for planning to win.

Observation vector, by ``view``:

* ``"absolute"`` (``2 (size-2)^2 + horizon`` floats): the interior's coin
  plane and agent plane (one-hot), flattened row-major, then the timestep
  one-hot. The wall plane is left out because it is the same in every state
  (the border is implicit in the planes' extent).
* ``"centred"`` (``2 (2 size - 5)^2 + horizon`` floats): a window centred on
  the agent, just wide enough to show the whole interior from any cell
  (``2 (size-2) - 1`` cells a side), as a coin plane and a wall plane (the
  border and everything off the grid), then the timestep one-hot. The agent
  is always the middle cell, so "a coin one step up" is the same input
  wherever the agent stands: with one hidden layer over absolute planes that
  rule has to be learnt once per cell.

Action features are identity one-hot rows either way: they describe the
move, not where it leads, since whether the agent can look ahead by itself is
what this project measures.

References, on the same initial states as the agent: the greedy nearest-coin
walker (Manhattan distance, ties to the lowest row-major cell, vertical moves
first) and a uniformly random walker (fixed key), both in JAX; and, for
``num_coins <= 12``, the exact optimum by dynamic programming over coin
subsets (NumPy, about 3 s per 1,000 instances of 12 coins). Measured over the
1,000 instances ``pizero eval --episodes 1000 --seed 0`` plays (default
parameters): greedy -1.031, random -8.900, optimal -0.405, with::

    JAX_PLATFORMS=cpu python -c "import jax, numpy as np, envs; from pizero_ray.agent.episodes import \\
      episode_reset_keys as k; env = envs.make('collect'); s, _ = jax.vmap(env.reset)(k(jax.random.PRNGKey(0), \\
      1000)); print(env.references(s, np.zeros(1000)))"
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from pizero_ray.envs.base import (
    Environment,
    EnvSpec,
    Observation,
    centred_window,
    identity_action_features,
    play_policy,
    require_choice,
    require_int,
)
from pizero_ray.envs.rendering import Header, canvas_with_header

NUM_MOVES = 4
# (row, column) offsets of the moves; row 0 is the top of the grid.
MOVES = np.array([[-1, 0], [0, 1], [1, 0], [0, -1]], dtype=np.int32)
UP, RIGHT, DOWN, LEFT = range(NUM_MOVES)
MAX_EXACT_COINS = 12
RANDOM_WALKER_SEED = 0
VIEWS = ("absolute", "centred")

class CollectState(NamedTuple):
    agent: jax.Array  # [2] int32: (row, column) on the full grid, walls included
    coins: jax.Array  # [size, size] bool: a coin lies on this cell
    t: jax.Array  # int32: steps taken


def border_walls(size: int) -> np.ndarray:
    """[size, size] bool: True on the border cells."""
    walls = np.ones((size, size), dtype=bool)
    walls[1:-1, 1:-1] = False
    return walls




def absolute_planes(state: CollectState) -> jax.Array:
    """The interior's coin plane, then its agent plane, flattened: [2 (size-2)^2]."""
    size = state.coins.shape[-1]
    agent = jnp.zeros((size, size), jnp.float32).at[state.agent[0], state.agent[1]].set(1.0)
    return jnp.concatenate([state.coins[1:-1, 1:-1].reshape(-1).astype(jnp.float32), agent[1:-1, 1:-1].reshape(-1)])


def centred_planes(state: CollectState) -> jax.Array:
    """Coin and wall planes of the window centred on the agent, flattened: [2 (2 size - 5)^2]."""
    size = state.coins.shape[-1]
    radius = size - 3  # from a corner of the interior, the far corner is size - 3 cells away
    coins = centred_window(state.coins, state.agent, radius, False)
    walls = centred_window(jnp.asarray(border_walls(size)), state.agent, radius, True)
    return jnp.concatenate([coins.reshape(-1), walls.reshape(-1)]).astype(jnp.float32)


def make(num_coins: int = 12, horizon: int = 20, size: int = 8, view: str = "absolute") -> Environment:
    require_int("collect", "size", size, 4)  # an interior of at least 2x2: room for the agent and a coin
    interior = size - 2
    require_int("collect", "num_coins", num_coins, 1, interior * interior - 1)
    require_int("collect", "horizon", horizon, 1)
    require_choice("collect", "view", view, VIEWS)
    walls = jnp.asarray(border_walls(size))
    interior_cells = jnp.asarray([(r, c) for r in range(1, size - 1) for c in range(1, size - 1)], dtype=jnp.int32)
    moves = jnp.asarray(MOVES)
    planes = centred_planes if view == "centred" else absolute_planes
    planes_size = 2 * (2 * interior - 1) ** 2 if view == "centred" else 2 * interior * interior

    def observe(state: CollectState) -> Observation:
        timestep = jax.nn.one_hot(state.t, horizon)  # all zeros once the episode is over
        vector = jnp.concatenate([planes(state), timestep])
        return Observation(vector, identity_action_features(NUM_MOVES), jnp.ones((NUM_MOVES,), bool))

    def reset(key: jax.Array) -> tuple[CollectState, Observation]:
        # Distinct cells: the first is the agent's, the rest hold the coins.
        cells = jax.random.choice(key, interior_cells, (num_coins + 1,), replace=False)
        coins = jnp.zeros((size, size), bool).at[cells[1:, 0], cells[1:, 1]].set(True)
        state = CollectState(cells[0], coins, jnp.int32(0))
        return state, observe(state)

    def step(state: CollectState, action: jax.Array):
        target = state.agent + moves[action.astype(jnp.int32)]
        agent = jnp.where(walls[target[0], target[1]], state.agent, target)
        coins = state.coins.at[agent[0], agent[1]].set(False)  # entering a coin's cell collects it
        state = CollectState(agent, coins, state.t + 1)
        done = state.t >= horizon
        reward = jnp.where(done, -coins.sum().astype(jnp.float32), 0.0)
        return state, observe(state), reward, done

    spec = EnvSpec(
        observation_size=planes_size + horizon,
        horizon=horizon,
        num_actions=NUM_MOVES,
        action_feature_size=NUM_MOVES,
    )
    return Environment(
        "collect", spec, reset, step,
        render=render,
        references=functools.partial(references, step=step, horizon=horizon, num_coins=num_coins),
    )


# ---------------------------------------------------------------- reference policies


def greedy_action(state: CollectState) -> jax.Array:
    """Towards the nearest coin (Manhattan; ties to the lowest row-major cell), vertical moves first."""
    size = state.coins.shape[-1]
    rows, columns = jnp.meshgrid(jnp.arange(size), jnp.arange(size), indexing="ij")
    distance = jnp.abs(rows - state.agent[0]) + jnp.abs(columns - state.agent[1])
    nearest = jnp.argmin(jnp.where(state.coins, distance, jnp.iinfo(jnp.int32).max).reshape(-1))  # first minimum
    row, column = nearest // size, nearest % size
    horizontal = jnp.where(column > state.agent[1], RIGHT, LEFT)
    vertical = jnp.where(row < state.agent[0], UP, DOWN)
    return jnp.where(row != state.agent[0], vertical, horizontal).astype(jnp.int32)


def walker_scores(step, horizon: int, initial_states: CollectState) -> tuple[jax.Array, jax.Array]:
    """Scores [E] of the greedy and the random walker on a batch of initial states."""
    episodes = initial_states.t.shape[0]
    keys = jax.random.split(jax.random.PRNGKey(RANDOM_WALKER_SEED), episodes)

    def greedy(state):
        return play_policy(step, lambda s, _, t: greedy_action(s), state, horizon).total_reward

    def random(state, key):
        def policy(s, _, t):
            return jax.random.randint(jax.random.fold_in(key, t), (), 0, NUM_MOVES)

        return play_policy(step, policy, state, horizon).total_reward

    return jax.jit(jax.vmap(greedy))(initial_states), jax.jit(jax.vmap(random))(initial_states, keys)


def optimal_coins_collected(agent: np.ndarray, coins: np.ndarray, horizon: int, chunk: int = 250) -> np.ndarray:
    """Most coins any walk of ``horizon`` moves collects; exact, batched ([E, 2] agents, [E, S, S] coins).

    On an open interior a walk through a set of coins costs the Manhattan
    length of its visiting order (coins passed on the way only help), so this
    is a shortest-Hamiltonian-path dynamic programme over subsets (Held-Karp):
    cost[S, j] = fewest moves that collect the coins in S, ending on j. Every
    instance must hold the same number of coins, at most ``MAX_EXACT_COINS``;
    episodes go ``chunk`` at a time to bound memory.
    """
    agent = np.asarray(agent, dtype=np.int32)
    coins = np.asarray(coins, dtype=bool)
    if agent.shape[0] > chunk:
        parts = [optimal_coins_collected(agent[i:i + chunk], coins[i:i + chunk], horizon, chunk)
                 for i in range(0, agent.shape[0], chunk)]
        return np.concatenate(parts)
    episodes, size = agent.shape[0], coins.shape[-1]
    flat = coins.reshape(episodes, -1)
    k = int(flat[0].sum())
    if not (flat.sum(axis=1) == k).all() or k > MAX_EXACT_COINS:
        raise ValueError(f"the exact optimum needs the same number of coins, at most {MAX_EXACT_COINS}, everywhere")
    cells = np.nonzero(flat)[1].reshape(episodes, k)  # [E, k] flat indices of the coins
    where = np.stack([cells // size, cells % size], axis=-1)  # [E, k, 2]
    from_agent = np.abs(where - agent[:, None, :]).sum(-1)  # [E, k]
    between = np.abs(where[:, :, None, :] - where[:, None, :, :]).sum(-1)  # [E, k, k]
    cost = np.zeros((episodes, 1 << k, k), dtype=np.int32)  # only entries with j in S are ever read
    cost[:, 1 << np.arange(k), np.arange(k)] = from_agent
    best = np.zeros(episodes, dtype=np.int32)
    for subset in range(1, 1 << k):
        members = [j for j in range(k) if subset >> j & 1]
        if len(members) > 1:
            for last in members:
                others = [j for j in members if j != last]
                cost[:, subset, last] = (cost[:, subset & ~(1 << last), others] + between[:, others, last]).min(1)
        reachable = cost[:, subset, members].min(axis=1) <= horizon
        best = np.where(reachable, np.maximum(best, len(members)), best)
    return best


def references(initial_states: CollectState, scores: np.ndarray, *, step, horizon: int,
               num_coins: int) -> dict[str, float]:
    """The greedy and random walkers' mean scores and, for few coins, the optimum, on the agent's instances."""
    greedy, random = walker_scores(step, horizon, initial_states)
    out = {"greedy_score": float(np.mean(greedy)), "random_score": float(np.mean(random))}
    if num_coins <= MAX_EXACT_COINS:
        optimal = optimal_coins_collected(initial_states.agent, initial_states.coins, horizon) - num_coins
        out["optimal_score"] = float(np.mean(optimal))
        out["mean_gap_to_optimal"] = float(np.mean(optimal) - np.mean(scores))
    return out


# ---------------------------------------------------------------- rendering

CELL = 64
HEADER = Header(height=30, text_origin=(8, 5), font_size=18, text_colour="black")
WALL_COLOUR = (60, 60, 70)
FLOOR_COLOUR = (235, 235, 225)
GRID_COLOUR = (200, 200, 190)
COIN_COLOUR = (240, 200, 30)
COIN_EDGE = (170, 130, 0)
AGENT_COLOUR = (40, 110, 220)


def render(state: CollectState) -> np.ndarray:
    """The grid (walls dark), coins as yellow circles, the agent as a blue disc, the coins left above."""
    coins = np.asarray(state.coins)
    size = coins.shape[0]
    walls = border_walls(size)
    image, draw = canvas_with_header(size * CELL, size * CELL, "white", HEADER, f"coins left {int(coins.sum())}")
    for r in range(size):
        for c in range(size):
            x, y = c * CELL, HEADER.height + r * CELL
            draw.rectangle((x, y, x + CELL - 1, y + CELL - 1), fill=WALL_COLOUR if walls[r, c] else FLOOR_COLOUR,
                           outline=None if walls[r, c] else GRID_COLOUR)
            if coins[r, c]:
                pad = CELL // 4
                draw.ellipse((x + pad, y + pad, x + CELL - pad, y + CELL - pad), fill=COIN_COLOUR, outline=COIN_EDGE,
                             width=2)
    r, c = np.asarray(state.agent).tolist()
    x, y, pad = c * CELL, HEADER.height + r * CELL, CELL // 8
    draw.ellipse((x + pad, y + pad, x + CELL - pad, y + CELL - pad), fill=AGENT_COLOUR)
    return np.asarray(image)
