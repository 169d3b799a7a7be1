"""Pac-Man, wrapped from Jumanji 1.1.2's ``PacMan`` (pure JAX, works offline), fully or partially observed.

The rules are Jumanji's, unchanged: the classic 31x28 maze (always the same
one), four ghosts with the classic chase / scatter heuristics and random
choices between equally good moves (the only randomness: each reset key
gives other ghost moves), rewards 10 per pellet, 50 per power pellet (whose
cell also holds a pellet: 60 in all) and 200 for a ghost eaten while
frightened (each ghost pays once per episode). A power pellet frightens the ghosts for 30 steps. The
episode ends when a ghost catches the player, all pellets are eaten, or at
``horizon`` steps, which is passed to Jumanji as its time limit (Jumanji's own
default is 1000). The score is the sum of Jumanji's rewards.

Actions follow Jumanji: 5 of them, 0..3 moves and 4 a no-op. Jumanji's docs
call the moves up, right, down, left, but in the maze as printed (row 0 at the
top, as the renderer draws it) they move up, left, down, right. Jumanji's
action mask allows the moves that do not hit a wall and never the no-op; it
is the observation's ``action_mask``. Action features are identity one-hot
rows.

Observations (``Observation.vector``), coordinates scaled to [0, 1):

* ``pacman`` (85 numbers): the player's (row, col); each ghost's (row, col);
  which ghosts still pay 200 when eaten; the frightened timer / 30; which
  power pellets remain; the remaining pellets per 4x4 block of the maze
  (8x7 = 56 fractions of the block's initial pellets); whether the 4
  neighbouring cells hold a pellet; the valid-move flags; the fraction of
  pellets left; the fraction of the horizon elapsed. The walls never change
  (one maze), so they are not in the vector.
* ``pacman-po`` (4 w^2 + 4 numbers): a w x w window centred on the player
  (``window_size``, odd, default 5) with four planes: wall, pellet, power
  pellet, ghost. Cells outside the maze count as wall, including the tunnel's ends,
  through which the player can still wrap. Then the player's own (row, col),
  the frightened timer / 30 (the player knows when it ate a power pellet)
  and the fraction of the horizon elapsed. Nothing outside the window: no
  ghost, pellet or power pellet beyond it; the GRU memory must remember.

Reference (``pizero eval``): a random player, uniform over the valid moves
with fixed keys, on the agent's initial states (the same ghost randomness).

Measured reference figures (1000 episodes, ``reference_scores`` below)::

    JAX_PLATFORMS=cpu python -c "import envs; from envs import pacman; \
        print(pacman.reference_scores(envs.make('pacman', horizon=H), 1000))"

    horizon  random score  caught by a ghost  mean episode length
    128      98.2          100%               25.5
    1000     98.2          100%               25.5

(the same for ``pacman-po``: the dynamics are the same). A random player is
always caught, after 25.5 steps on average, so the horizon does not matter to
it; 128 (the default) leaves an agent that evades the ghosts room to score
several times more while keeping episodes cheap on CPU.

Beware: the ghosts' random choices matter only at ties, so given the same
actions different reset keys give nearly the same game (one score for 200
keys under one fixed action sequence). A deterministic agent plays the same
episode every time: extra episodes per member add little, and evaluation scores have
almost no spread.

Training presets for both variants (a smaller population; Jumanji's full
1000-step game in "paper") are in ``pizero_ray.presets``.
"""

from __future__ import annotations

import functools
from typing import Any, NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from pizero_ray.envs.base import (
    Environment,
    EnvSpec,
    Observation,
    fresh_initial_states,
    identity_action_features,
    mean_reference_metrics,
    random_legal_action,
    reference_player,
    require,
    require_bool,
    require_int,
)
from pizero_ray.envs.rendering import Header, canvas_with_header

NUM_ACTIONS = 5  # Jumanji's: 4 moves and a no-op
NUM_MOVES = 4
NUM_GHOSTS = 4
FRIGHTENED_STEPS = 30  # Jumanji sets the timer to 30 when a power pellet is eaten
BLOCK = 4  # side of the blocks of the full observation's coarse pellet map
NEIGHBOURS = np.array([[-1, 0], [0, -1], [1, 0], [0, 1]])  # (row, col) offsets of moves 0..3
PLANES = ("wall", "pellet", "power pellet", "ghost")
REFERENCE_SEED = 7
GHOST_COLOURS = ((230, 30, 30), (250, 160, 210), (40, 220, 230), (250, 170, 50))

class PacManState(NamedTuple):
    game: Any  # Jumanji's pac_man State; positions are Position(x=row, y=col), arrays hold (col, row)


def reseed(state: PacManState, key: jax.Array) -> PacManState:
    """The same position, the ghosts' future random choices drawn from ``key`` (Jumanji keeps it in its state)."""
    return PacManState(state.game.replace(key=key))


class Maze(NamedTuple):
    """What never changes: the free cells and where pellets start (NumPy, [rows, cols])."""

    free: np.ndarray  # bool
    initial_pellets: np.ndarray  # bool
    initial_block_pellets: np.ndarray  # float32 [blocks down, blocks across]: pellets per BLOCK x BLOCK block

    @property
    def shape(self) -> tuple[int, int]:
        return self.free.shape


def maze_from(generator) -> Maze:
    """The static maze of a Jumanji PacMan generator (its grid: 1 = free, 0 = wall; pellets as (col, row))."""
    free = np.asarray(generator.numpy_maze) == 1
    pellets_col_row = np.asarray(generator.pellet_spaces)
    initial_pellets = np.zeros(free.shape, bool)
    initial_pellets[pellets_col_row[:, 1], pellets_col_row[:, 0]] = True
    return Maze(free, initial_pellets, np.asarray(block_sums(jnp.asarray(initial_pellets, jnp.float32))))


# ---------------------------------------------------------------- reading Jumanji's state


def player_cell(game) -> jax.Array:
    """(row, col) of the player."""
    return jnp.stack([game.player_locations.x, game.player_locations.y]).astype(jnp.int32)


def ghost_cells(game) -> jax.Array:
    """[4, 2] (row, col) of the ghosts (Jumanji stores (col, row))."""
    return game.ghost_locations[:, ::-1].astype(jnp.int32)


def cells_grid(shape: tuple[int, int], cells_col_row: jax.Array) -> jax.Array:
    """A bool [rows, cols] map of (col, row) locations; Jumanji parks eaten items at (0, 0), a wall."""
    grid = jnp.zeros(shape, bool).at[cells_col_row[:, 1], cells_col_row[:, 0]].set(True)
    return grid.at[0, 0].set(False)


def pellet_grid(maze: Maze, game) -> jax.Array:
    return cells_grid(maze.shape, game.pellet_locations)


def power_pellet_grid(maze: Maze, game) -> jax.Array:
    return cells_grid(maze.shape, game.power_up_locations)


def ghost_grid(maze: Maze, game) -> jax.Array:
    cells = ghost_cells(game)
    return jnp.zeros(maze.shape, bool).at[cells[:, 0], cells[:, 1]].set(True)


def window(plane: jax.Array, centre: jax.Array, size: int, outside: bool) -> jax.Array:
    """The size x size part of a [rows, cols] plane centred on ``centre``; cells beyond the maze are ``outside``."""
    half = size // 2
    padded = jnp.pad(plane, half, constant_values=outside)
    return jax.lax.dynamic_slice(padded, (centre[0], centre[1]), (size, size))


def coarse_pellets(maze: Maze, pellets: jax.Array) -> jax.Array:
    """Fraction of each BLOCK x BLOCK block's initial pellets still there (0 for blocks without pellets)."""
    initial = maze.initial_block_pellets
    return jnp.where(initial > 0, block_sums(pellets.astype(jnp.float32)) / np.maximum(initial, 1.0), 0.0).reshape(-1)


def block_sums(plane: jax.Array) -> jax.Array:
    """Sums over BLOCK x BLOCK blocks of a [rows, cols] plane (zero-padded at the bottom and right)."""
    rows, cols = plane.shape
    padded_rows, padded_cols = -(-rows // BLOCK) * BLOCK, -(-cols // BLOCK) * BLOCK
    padded = jnp.pad(plane, ((0, padded_rows - rows), (0, padded_cols - cols)))
    return padded.reshape(padded_rows // BLOCK, BLOCK, padded_cols // BLOCK, BLOCK).sum(axis=(1, 3))


# ---------------------------------------------------------------- observations


def full_vector(maze: Maze, game, horizon: int, mask: jax.Array) -> jax.Array:
    scale = np.array(maze.shape, np.float32)
    player = player_cell(game)
    pellets = pellet_grid(maze, game)
    neighbours = (player + NEIGHBOURS) % np.array(maze.shape)  # the tunnel wraps around
    return jnp.concatenate([
        player / scale,
        (ghost_cells(game) / scale).reshape(-1),
        game.ghost_eaten.astype(jnp.float32),
        jnp.reshape(game.frightened_state_time.clip(0) / FRIGHTENED_STEPS, (1,)),
        jnp.any(game.power_up_locations != 0, axis=-1).astype(jnp.float32),
        coarse_pellets(maze, pellets),
        pellets[neighbours[:, 0], neighbours[:, 1]].astype(jnp.float32),
        mask[:NUM_MOVES].astype(jnp.float32),
        jnp.reshape(game.pellets / maze.initial_pellets.sum(), (1,)),
        jnp.reshape(game.step_count / horizon, (1,)),
    ]).astype(jnp.float32)


def full_vector_size(maze: Maze) -> int:
    rows, cols = maze.shape
    blocks = -(-rows // BLOCK) * -(-cols // BLOCK)
    return 2 + 2 * NUM_GHOSTS + NUM_GHOSTS + 1 + 4 + blocks + NUM_MOVES + NUM_MOVES + 1 + 1


def window_planes(maze: Maze, game, size: int) -> jax.Array:
    """[4, size, size]: wall, pellet, power pellet and ghost planes of the window around the player."""
    centre = player_cell(game)
    planes = [
        window(jnp.asarray(~maze.free), centre, size, outside=True),
        window(pellet_grid(maze, game), centre, size, outside=False),
        window(power_pellet_grid(maze, game), centre, size, outside=False),
        window(ghost_grid(maze, game), centre, size, outside=False),
    ]
    return jnp.stack(planes)


def partial_vector_size(size: int) -> int:
    return len(PLANES) * size * size + 2 + 1 + 1


def partial_vector(maze: Maze, game, horizon: int, size: int) -> jax.Array:
    scale = np.array(maze.shape, np.float32)
    return jnp.concatenate([
        window_planes(maze, game, size).astype(jnp.float32).reshape(-1),
        player_cell(game) / scale,
        jnp.reshape(game.frightened_state_time.clip(0) / FRIGHTENED_STEPS, (1,)),
        jnp.reshape(game.step_count / horizon, (1,)),
    ]).astype(jnp.float32)


# ---------------------------------------------------------------- the environment


def make(partial: bool = False, horizon: int = 128, window_size: int | None = None) -> Environment:
    """Pac-Man cut at ``horizon`` steps; ``partial`` shows only a ``window_size`` window (odd, default 5)."""
    require_bool("pacman", "partial", partial)
    name = "pacman-po" if partial else "pacman"
    require_int(name, "horizon", horizon, 1)
    if not partial:
        require(window_size is None, name, "window_size", window_size, "left out (it applies to pacman-po only)")
    size = 5 if window_size is None else window_size
    require_int(name, "window_size", size, 1, odd=True)
    from jumanji.environments import PacMan  # imported here: importing jumanji takes a second or two

    game = PacMan(time_limit=horizon)
    maze = maze_from(game.generator)
    features = identity_action_features(NUM_ACTIONS)

    def observe(state: PacManState, mask: jax.Array) -> Observation:
        if partial:
            vector = partial_vector(maze, state.game, horizon, size)
        else:
            vector = full_vector(maze, state.game, horizon, mask)
        return Observation(vector, features, mask)

    def reset(key: jax.Array) -> tuple[PacManState, Observation]:
        game_state, timestep = game.reset(key)
        state = PacManState(game_state)
        return state, observe(state, timestep.observation.action_mask)

    def step(state: PacManState, action: jax.Array):
        game_state, timestep = game.step(state.game, action.astype(jnp.int32))
        state = PacManState(game_state)
        observation = observe(state, timestep.observation.action_mask)
        # Jumanji's end: caught by a ghost, all pellets eaten, or its time limit (= horizon)
        return state, observation, timestep.reward.astype(jnp.float32), timestep.last()

    observation_size = partial_vector_size(size) if partial else full_vector_size(maze)
    spec = EnvSpec(observation_size, horizon, NUM_ACTIONS, NUM_ACTIONS)
    draw = functools.partial(render, maze, size if partial else None)
    env = Environment(name, spec, reset, step, render=draw, reseed=reseed)
    return env._replace(references=functools.partial(references, make_random_player(env)))


# ---------------------------------------------------------------- reference player


PLAYER_METRICS = ("score", "caught", "length")  # what the random player returns per episode


def make_random_player(env: Environment):
    """jit(initial states [E], keys [E]) -> (scores, caught by a ghost, episode lengths) of the random player."""

    def step(state: PacManState, action: jax.Array):
        state, observation, reward, done = env.step(state, action)
        return state, observation.action_mask, reward, done  # all the player reads of the observation

    def policy(state: PacManState, mask: jax.Array, key: jax.Array) -> jax.Array:
        return random_legal_action(mask, key)  # uniform over the valid moves

    def summarise(playout):
        # the state where the episode ended: a catch always ends it, so ``dead`` there says whether it was one
        return playout.total_reward, playout.final_state.game.dead, playout.length

    return reference_player(step, policy, env.spec.horizon, summarise, action_mask_of)


def action_mask_of(state: PacManState) -> jax.Array:
    """Jumanji's action mask, rebuilt from a state: moves onto free cells, never the no-op."""
    game = state.game
    cell = player_cell(game)
    rows, cols = game.grid.shape
    neighbours = (cell + NEIGHBOURS) % jnp.array([rows, cols])
    moves = game.grid[neighbours[:, 0], neighbours[:, 1]] == 1
    return jnp.concatenate([moves, jnp.zeros((1,), bool)])


def references(random_player, initial_states: PacManState, scores: np.ndarray) -> dict[str, float]:
    """The random player's mean score on the agent's initial states."""
    means = mean_reference_metrics({"random": random_player}, PLAYER_METRICS, initial_states, REFERENCE_SEED)
    return {"random_score": means["random_score"]}


def reference_scores(env: Environment, episodes: int = 1000, seed: int = 0) -> dict[str, float]:
    """The reference figures on ``episodes`` fresh initial states (for the docstring's table)."""
    players = {"random": make_random_player(env)}
    return mean_reference_metrics(players, PLAYER_METRICS, fresh_initial_states(env, episodes, seed), REFERENCE_SEED)


# ---------------------------------------------------------------- rendering

HEADER = Header(height=22, text_origin=(4, 3), font_size=14, text_colour="white")


def render(maze: Maze, window_size: int | None, state: PacManState, cell: int = 12) -> np.ndarray:
    """The maze, pellets, power pellets, ghosts and player; for pacman-po the visible window's outline.

    Above the maze: the pellets left, and whether the player is caught or the ghosts frightened.
    """
    game = state.game
    rows, cols = maze.shape
    pellets = np.zeros(maze.shape, bool)
    locations = np.asarray(game.pellet_locations)
    pellets[locations[:, 1], locations[:, 0]] = True
    pellets[0, 0] = False
    frightened = int(np.asarray(game.frightened_state_time)) > 0
    caught = bool(np.asarray(game.dead))
    status = "caught" if caught else ("frightened" if frightened else "")
    header_text = f"pellets left {int(pellets.sum())}  {status}"
    image, draw = canvas_with_header(cols * cell, rows * cell, "black", HEADER, header_text)
    top = HEADER.height
    box = lambda r, c, inset=0: (c * cell + inset, top + r * cell + inset,
                                 (c + 1) * cell - 1 - inset, top + (r + 1) * cell - 1 - inset)
    for r, c in zip(*np.nonzero(~maze.free)):
        draw.rectangle(box(r, c), fill=(20, 30, 120))
    for r, c in zip(*np.nonzero(pellets)):
        draw.ellipse(box(r, c, cell // 2 - 2), fill=(255, 200, 170))
    for c, r in np.asarray(game.power_up_locations):
        if (r, c) != (0, 0):
            draw.ellipse(box(r, c, 1), fill=(255, 200, 170))
    for (c, r), colour in zip(np.asarray(game.ghost_locations), GHOST_COLOURS):
        x0, y0, x1, y1 = box(r, c, 1)
        fill = (90, 110, 255) if frightened else colour
        draw.pieslice((x0, y0, x1, y1 + (y1 - y0) // 2), 180, 360, fill=fill)  # the head
        draw.rectangle((x0, (y0 + y1) // 2, x1, y1), fill=fill)  # the skirt
    player_r, player_c = int(np.asarray(game.player_locations.x)), int(np.asarray(game.player_locations.y))
    facing = {0: 270, 1: 180, 2: 90, 3: 0}.get(int(np.asarray(game.last_direction)), 0)  # PIL angles, clockwise
    if caught:  # a small grey player on top of the ghost that caught it
        draw.ellipse(box(player_r, player_c, 3), fill=(170, 170, 170))
    else:
        draw.pieslice(box(player_r, player_c, 0), facing + 35, facing + 325, fill=(255, 230, 0))
    if window_size is not None:
        half = window_size // 2
        x0, y0, _, _ = box(player_r - half, player_c - half)
        _, _, x1, y1 = box(player_r + half, player_c + half)
        width, height = image.size  # at the border the window reaches beyond the maze: outline what is on screen
        draw.rectangle((max(x0, 0), max(y0, top), min(x1, width - 1), min(y1, height - 1)),
                       outline=(60, 255, 90), width=2)
    return np.asarray(image)
