"""2048, wrapped from Jumanji 1.1.2's ``Game2048`` (pure JAX, works offline).

The rules are Jumanji's, unchanged: a 4x4 board, actions 0..3 = up, right,
down, left; a move slides and merges tiles, and the reward is the sum of the
tiles created by merges, so the episode's return is the usual game score.
After every move that changes the board a tile (2 with probability 0.9, else
4) appears on an empty cell.

Jumanji's quirks and what this wrapper does about them:

* The game starts with one tile, not two (kept: it is Jumanji's game).
* A move that changes nothing is a silent no-op (no tile appears). Jumanji's
  mask of valid moves is the observation's ``action_mask``, so the agent never
  wastes a step on one; when no move is valid the game is over (``done``).
* There is no time limit. ``horizon`` (default 200) bounds an episode so ES
  rollouts have a fixed length. A masked random player's game lasts 121 moves
  on average (3.6% go beyond 200), a greedy player's 259 (69% go beyond 200),
  so a decent agent is cut off by the horizon: raise it for longer games.

Observation vector: the board's 16 cells as exponents (log2 of the tile, 0 for
empty) divided by 16, or with ``tile_encoding="one_hot"`` each cell's exponent
one-hot over 0..15 (256 numbers); then the 4 valid-move flags and the fraction
of the horizon elapsed. Action features are identity one-hot rows: they
describe the move itself, no lookahead.

References (``pizero eval``), on the same initial states as the agent and with
the same horizon, in JAX: a random player (uniform over valid moves, fixed
keys) and a greedy one-step player (the valid move with the largest immediate
merge reward; ties go to the lowest action index), their mean game scores and
mean highest tiles.

Measured reference figures (1000 episodes, ``reference_scores`` below)::

    JAX_PLATFORMS=cpu python -c "import envs; from envs import game2048; \
        print(game2048.reference_scores(envs.make('2048', horizon=H), 1000))"

    horizon  random score  random top tile  greedy score  greedy top tile
    200      1081          106.5            2130          196.2
    5000     1091          106.5            3080          239.0

A random game lasts 121 moves on average (99th percentile 224, longest 251),
so with a long horizon ~1,090 is the complete random game's score, in line
with the ~1,100 the paper quotes. A greedy game lasts 259 moves on average
(10th-90th percentile 155-397, longest 675): horizon 200 cuts 69% of them.

Training presets for 2048 (a smaller population; 1000-move games in "paper")
are in ``pizero_ray.presets``.
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
    require_choice,
    require_int,
)
from pizero_ray.envs.rendering import Header, canvas_with_header, font

NUM_MOVES = 4
BOARD_SIZE = 4
MAX_EXPONENT = 16  # scale for exponents; a 4x4 board cannot in practice pass 2^16 = 65536
TILE_ENCODINGS = ("log2", "one_hot")
REFERENCE_SEED = 2048  # fixed keys of the random reference player

class Game2048State(NamedTuple):
    game: Any  # Jumanji's game_2048 State (board of exponents, step_count, action_mask, score, key)


def reseed(state: Game2048State, key: jax.Array) -> Game2048State:
    """The same board, its future tiles drawn from ``key`` (Jumanji keeps the key for the next tile in its state)."""
    return Game2048State(state.game.replace(key=key))


def episode_metrics(final_states: Game2048State) -> dict[str, np.ndarray]:
    """The agent's highest tile in each evaluated game."""
    return {"highest_tile": np.asarray(jax.vmap(highest_tile)(final_states.game.board))}


def highest_tile(board: jax.Array) -> jax.Array:
    """Value of the largest tile on a board of exponents (0 on an empty board)."""
    top = jnp.max(board)
    return jnp.where(top > 0, 2**top, 0).astype(jnp.int32)


def merge_rewards(board: jax.Array) -> jax.Array:
    """The immediate merge reward of each of the 4 moves (0 for moves that merge nothing)."""
    from jumanji.environments.logic.game_2048.utils import move

    return jax.vmap(lambda action: move(board, action)[1])(jnp.arange(NUM_MOVES)).astype(jnp.float32)


def make(horizon: int = 200, tile_encoding: str = "log2") -> Environment:
    """2048 with episodes cut at ``horizon`` moves; ``tile_encoding`` is "log2" or "one_hot"."""
    require_int("2048", "horizon", horizon, 1)
    require_choice("2048", "tile_encoding", tile_encoding, TILE_ENCODINGS)
    from jumanji.environments import Game2048  # imported here: importing jumanji takes a second or two

    game = Game2048(board_size=BOARD_SIZE)
    features = identity_action_features(NUM_MOVES)

    def encode_board(board: jax.Array) -> jax.Array:
        if tile_encoding == "one_hot":
            return jax.nn.one_hot(jnp.minimum(board, MAX_EXPONENT - 1), MAX_EXPONENT).reshape(-1)
        return board.reshape(-1).astype(jnp.float32) / MAX_EXPONENT

    def observe(state: Game2048State) -> Observation:
        mask = state.game.action_mask
        progress = state.game.step_count.astype(jnp.float32) / horizon
        vector = jnp.concatenate([encode_board(state.game.board), mask.astype(jnp.float32), progress[None]])
        return Observation(vector, features, mask)

    def reset(key: jax.Array) -> tuple[Game2048State, Observation]:
        game_state, _ = game.reset(key)
        state = Game2048State(game_state)
        return state, observe(state)

    def step(state: Game2048State, action: jax.Array):
        game_state, timestep = game.step(state.game, action.astype(jnp.int32))
        state = Game2048State(game_state)
        no_valid_move = ~jnp.any(game_state.action_mask)
        done = no_valid_move | (game_state.step_count >= horizon)
        return state, observe(state), timestep.reward.astype(jnp.float32), done

    board_cells = BOARD_SIZE * BOARD_SIZE
    tile_size = board_cells * (MAX_EXPONENT if tile_encoding == "one_hot" else 1)
    spec = EnvSpec(
        observation_size=tile_size + NUM_MOVES + 1,
        horizon=horizon,
        num_actions=NUM_MOVES,
        action_feature_size=NUM_MOVES,
    )
    env = Environment("2048", spec, reset, step, render=render, episode_metrics=episode_metrics, reseed=reseed)
    players = {"random": make_player(env, greedy=False), "greedy": make_player(env, greedy=True)}
    return env._replace(references=functools.partial(references, players))


# ---------------------------------------------------------------- reference players


def greedy_policy(state: Game2048State) -> jax.Array:
    """The valid move with the largest immediate merge reward; ties go to the lowest index."""
    rewards = jnp.where(state.game.action_mask, merge_rewards(state.game.board), -1.0)
    return jnp.argmax(rewards).astype(jnp.int32)


PLAYER_METRICS = ("score", "highest_tile")  # what a player returns per episode


def make_player(env: Environment, greedy: bool):
    """jit(initial states [E], keys [E]) -> (scores, highest tiles): a reference player to the horizon."""

    def policy(state: Game2048State, _, key: jax.Array) -> jax.Array:
        # random: uniform over the valid moves (move 0 when none is valid: the game is over anyway)
        return greedy_policy(state) if greedy else random_legal_action(state.game.action_mask, key)

    def summarise(playout):
        return playout.total_reward, highest_tile(playout.final_state.game.board)

    return reference_player(env.step, policy, env.spec.horizon, summarise)


def references(players: dict, initial_states: Game2048State, scores: np.ndarray) -> dict[str, float]:
    """Random and greedy one-step players on the agent's initial states: mean score and highest tile."""
    return mean_reference_metrics(players, PLAYER_METRICS, initial_states, REFERENCE_SEED)


def reference_scores(env: Environment, episodes: int = 1000, seed: int = 0) -> dict[str, float]:
    """The reference figures on ``episodes`` fresh initial states (for the docstring's table)."""
    return env.references(fresh_initial_states(env, episodes, seed), np.zeros(episodes))


# ---------------------------------------------------------------- rendering

_TILE_COLOURS = {
    0: (205, 193, 180), 2: (238, 228, 218), 4: (237, 224, 200), 8: (242, 177, 121), 16: (245, 149, 99),
    32: (246, 124, 95), 64: (246, 94, 59), 128: (237, 207, 114), 256: (237, 204, 97), 512: (237, 200, 80),
    1024: (237, 197, 63), 2048: (237, 194, 46),
}
_BIG_TILE_COLOUR = (60, 58, 50)
_BOARD_COLOUR = (187, 173, 160)
_DARK_TEXT, _LIGHT_TEXT = (119, 110, 101), (249, 246, 242)
HEADER = Header(height=44, text_origin=(12, 10), font_size=22, text_colour=_DARK_TEXT)  # x: render's default gap


def render(state: Game2048State, tile: int = 120, gap: int = 12) -> np.ndarray:
    """The board like the game: coloured tiles with their numbers, the highest tile above."""
    board = np.asarray(state.game.board)
    n = board.shape[0]
    side = n * tile + (n + 1) * gap
    top = int(2 ** board.max()) if board.max() > 0 else 0
    header = HEADER._replace(text_origin=(gap, HEADER.text_origin[1]))  # the text in line with the first tile
    image, draw = canvas_with_header(side, side, (250, 248, 239), header, f"highest tile {top}")
    draw.rounded_rectangle((0, header.height, side - 1, side + header.height - 1), radius=8, fill=_BOARD_COLOUR)
    for row in range(n):
        for col in range(n):
            value = int(2 ** board[row, col]) if board[row, col] > 0 else 0
            x0, y0 = gap + col * (tile + gap), header.height + gap + row * (tile + gap)
            draw.rounded_rectangle(
                (x0, y0, x0 + tile, y0 + tile), radius=6, fill=_TILE_COLOURS.get(value, _BIG_TILE_COLOUR)
            )
            if value:
                text = str(value)
                colour = _DARK_TEXT if value <= 4 else _LIGHT_TEXT
                draw.text((x0 + tile / 2, y0 + tile / 2), text, fill=colour,
                          font=font(int(tile * min(0.45, 1.1 / len(text)))), anchor="mm")
    return np.asarray(image)
