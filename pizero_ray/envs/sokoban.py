"""Sokoban on 10x10 Boxoban-style levels (PiZero's Sokoban).

Rules: the agent moves up, down, left or right (actions 0-3). Moving onto a
box pushes it one cell if the cell beyond is floor or an empty goal; a box is
never pulled, and a move into a wall, or a push into a wall or another box,
leaves everything in place. Cells off the grid count as walls.

Score: as in the paper, the number of goals covered by boxes at the end of the
episode (horizon H = 50 by default). Each step's reward is the change in
covered goals, and the first step also pays the goals covered at reset, so the
rewards of an episode sum to the goals covered at its end. An episode ends
early once every box is on a goal (the score is then the number of boxes).

Levels: ``levels=PATH`` loads Boxoban text files (one file, or every *.txt
under a directory; see ``envs.boxoban``). Without it, a bank of ``num_levels``
levels with ``num_boxes`` boxes is generated from ``generator_seed`` by reverse
play (``pizero_ray.envs.sokoban_generator``); the generator parameters are ignored when
levels are loaded, so a run trained on generated levels can be evaluated on
Boxoban files with ``--env-arg levels=PATH``. Either way the bank is an int8
array [L, 10, 10] inside the program and ``reset`` samples a level uniformly
with ``jax.random.randint``. (The bank is a compile-time constant, 100 bytes
a level: fine for the 20k-level subsets used here; split larger sets.)

Observation, by ``view``, then the fraction of the horizon elapsed:

* ``"absolute"``: four binary 10x10 planes (wall, goal, box, player; floor
  is "not wall") flattened: 401 numbers.
* ``"centred"``: wall, goal and box planes of the ``2 view_radius + 1``
  square window centred on the player (off the grid reads as wall), so the
  player is always the middle cell and "a wall just above" is the same input
  wherever the player stands: ``3 (2 view_radius + 1)^2 + 1`` numbers (244
  at the default radius 4, which shows most of the room; 9 shows all of it
  from anywhere).
Action features are identity rows: they name the move and say nothing about
its consequences, so any lookahead has to come from the agent.

References (``pizero eval``): the agent's solved fraction, and a uniformly
random agent on the same initial states (fixed key). On every level of a bank
once, H = 50, measured with ``JAX_PLATFORMS=cpu python -m pizero_ray.envs.sokoban [PATH]``:

    levels                                   random goals covered   random solved
    generated (default: 1000, seed 0)        0.42 of 4              0.0 %
    boxoban unfiltered/valid (1000 levels)   0.34 of 4              0.0 %
    boxoban medium/valid (1000 levels)       0.29 of 4              0.0 %
"""

from __future__ import annotations

import functools
import sys
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from pizero_ray.envs import boxoban, sokoban_generator
from pizero_ray.envs.base import (
    Environment,
    EnvSpec,
    Observation,
    centred_window,
    identity_action_features,
    play_policy,
    require_choice,
    require_int,
    require_path,
)
from pizero_ray.envs.rendering import Header, canvas_with_header

ROOM_SIZE = boxoban.ROOM_SIZE
MOVES = np.array([[-1, 0], [1, 0], [0, -1], [0, 1]], dtype=np.int32)  # up, down, left, right (row, column)
ACTION_NAMES = ("up", "down", "left", "right")
NUM_PLANES = 4  # wall, goal, box, player
VIEWS = ("absolute", "centred")
DEFAULT_HORIZON = 50
RANDOM_AGENT_SEED = 20170801  # fixed: the random reference is the same on every evaluation

class SokobanState(NamedTuple):
    walls: jax.Array  # [10, 10] bool
    goals: jax.Array  # [10, 10] bool
    boxes: jax.Array  # [10, 10] bool
    player: jax.Array  # [2] int32: (row, column)
    t: jax.Array  # int32: steps taken
    level: jax.Array  # int32: index of the level in the bank (for rendering and debugging)


def state_from_codes(codes: jax.Array, level: jax.Array | int = 0) -> SokobanState:
    """The start of a level from its tile codes [10, 10] (see ``envs.boxoban``); jittable."""
    codes = jnp.asarray(codes)
    is_player = jnp.isin(codes, jnp.array(boxoban.PLAYER_CODES, jnp.int8))
    player = jnp.stack(jnp.divmod(jnp.argmax(is_player.reshape(-1)), ROOM_SIZE)).astype(jnp.int32)
    return SokobanState(
        walls=codes == boxoban.WALL,
        goals=jnp.isin(codes, jnp.array(boxoban.GOAL_CODES, jnp.int8)),
        boxes=jnp.isin(codes, jnp.array(boxoban.BOX_CODES, jnp.int8)),
        player=player,
        t=jnp.int32(0),
        level=jnp.asarray(level, jnp.int32),
    )


def covered_goals(state: SokobanState) -> jax.Array:
    return jnp.sum(state.boxes & state.goals, axis=(-2, -1))


def is_solved(state: SokobanState) -> jax.Array:
    return ~jnp.any(state.boxes & ~state.goals, axis=(-2, -1))


def _cell(position: jax.Array) -> jax.Array:
    """A [10, 10] mask of one cell; all False when the position is off the grid."""
    rows = jnp.arange(ROOM_SIZE)[:, None]
    cols = jnp.arange(ROOM_SIZE)[None, :]
    return (rows == position[0]) & (cols == position[1])


def move(state: SokobanState, action: jax.Array) -> SokobanState:
    """The Sokoban rules for one move (time not advanced); masks, not indexing, so off-grid is safe."""
    direction = jnp.asarray(MOVES)[action]
    target, beyond = _cell(state.player + direction), _cell(state.player + 2 * direction)
    target_blocked = ~target.any() | (state.walls & target).any()  # off the grid is a wall
    target_box = (state.boxes & target).any()
    beyond_free = beyond.any() & ~((state.walls | state.boxes) & beyond).any()
    moves = ~target_blocked & (~target_box | beyond_free)
    pushes = moves & target_box
    boxes = jnp.where(pushes, (state.boxes & ~target) | beyond, state.boxes)
    player = jnp.where(moves, state.player + direction, state.player)
    return state._replace(boxes=boxes, player=player)


def absolute_planes(state: SokobanState) -> jax.Array:
    """The wall, goal, box and player planes of the room, flattened: [400]."""
    return jnp.stack([state.walls, state.goals, state.boxes, _cell(state.player)]).astype(jnp.float32).reshape(-1)


def centred_planes(state: SokobanState, radius: int) -> jax.Array:
    """The wall, goal and box planes of the window centred on the player, flattened: [3 (2 radius + 1)^2]."""
    window = [centred_window(plane, state.player, radius, fill)
              for plane, fill in ((state.walls, True), (state.goals, False), (state.boxes, False))]
    return jnp.stack(window).astype(jnp.float32).reshape(-1)


def make(
    levels: str | None = None,
    horizon: int = DEFAULT_HORIZON,
    num_levels: int = 1000,
    num_boxes: int = 4,
    generator_seed: int = 0,
    pull_rounds: int = 8,
    view: str = "absolute",
    view_radius: int = 4,
) -> Environment:
    require_int("sokoban", "horizon", horizon, 1)
    require_choice("sokoban", "view", view, VIEWS)
    require_int("sokoban", "view_radius", view_radius, 1, ROOM_SIZE - 1)
    planes = functools.partial(centred_planes, radius=view_radius) if view == "centred" else absolute_planes
    planes_size = 3 * (2 * view_radius + 1) ** 2 if view == "centred" else NUM_PLANES * ROOM_SIZE * ROOM_SIZE
    bank = level_bank(levels, num_levels, num_boxes, generator_seed, pull_rounds)
    codes = jnp.asarray(bank)
    num_bank_levels = bank.shape[0]

    def observe(state: SokobanState) -> Observation:
        elapsed = (state.t / horizon).astype(jnp.float32)
        vector = jnp.concatenate([planes(state), elapsed[None]])
        return Observation(vector, identity_action_features(len(MOVES)), jnp.ones((len(MOVES),), dtype=bool))

    def reset(key: jax.Array) -> tuple[SokobanState, Observation]:
        level = jax.random.randint(key, (), 0, num_bank_levels)
        state = state_from_codes(codes[level], level)
        return state, observe(state)

    def step(state: SokobanState, action: jax.Array):
        before = covered_goals(state)
        after_move = move(state, action.astype(jnp.int32))
        state = after_move._replace(t=state.t + 1)
        after = covered_goals(state)
        # rewards sum to the goals covered at the end: the first step also pays what reset covered
        reward = (after - before + jnp.where(state.t == 1, before, 0)).astype(jnp.float32)
        done = is_solved(state) | (state.t >= horizon)
        return state, observe(state), reward, done

    spec = EnvSpec(
        observation_size=planes_size + 1,
        horizon=horizon,
        num_actions=len(MOVES),
        action_feature_size=len(MOVES),
    )
    return Environment(
        "sokoban",
        spec,
        reset,
        step,
        render=render,
        references=functools.partial(references, random_agent=_random_agent(step, horizon)),
    )




def level_bank(levels: str | None, num_levels: int, num_boxes: int, generator_seed: int, pull_rounds: int):
    """Tile codes int8 [L, 10, 10]: the loaded files, or the generated bank."""
    # generator parameters are checked even when files are loaded: a bad value is a mistake either way
    require_int("sokoban", "num_levels", num_levels, 1)
    require_int("sokoban", "num_boxes", num_boxes, 1, sokoban_generator.MAX_BOXES)
    require_int("sokoban", "generator_seed", generator_seed, 0)
    require_int("sokoban", "pull_rounds", pull_rounds, 1)
    if levels is not None:
        require_path("sokoban", "levels", levels)
        try:
            return boxoban.load_levels(levels)
        except ValueError as error:
            raise ValueError(f"sokoban: {error}") from None
    try:
        return sokoban_generator.generate_levels(num_levels, num_boxes, generator_seed, pull_rounds).codes
    except ValueError as error:
        raise ValueError(f"sokoban: {error}") from None


# ---------------------------------------------------------------- references


def random_agent_scores(step, initial_states: SokobanState, horizon: int, key: jax.Array) -> jax.Array:
    """Goals covered at the end by uniformly random moves, one episode per initial state (jittable)."""

    def episode(state: SokobanState, episode_key: jax.Array) -> jax.Array:
        actions = jax.random.randint(episode_key, (horizon,), 0, len(MOVES))
        return play_policy(step, lambda s, _, t: actions[t], state, horizon).total_reward

    keys = jax.random.split(key, initial_states.t.shape[0])
    return jax.vmap(episode)(initial_states, keys)


def _random_agent(step, horizon: int):
    """The random reference, compiled once per environment (per batch size), with its fixed key."""
    scores = jax.jit(lambda states, key: random_agent_scores(step, states, horizon, key))
    return lambda initial_states: scores(initial_states, jax.random.PRNGKey(RANDOM_AGENT_SEED))


def references(initial_states: SokobanState, scores: np.ndarray, *, random_agent) -> dict[str, float]:
    """The agent's solved fraction, and a random agent's goals covered and solved fraction, same levels."""
    num_boxes = np.asarray(initial_states.boxes).sum(axis=(-2, -1))
    scores = np.asarray(scores, dtype=np.float64)
    random_scores = np.asarray(random_agent(initial_states), dtype=np.float64)
    return {
        "mean_boxes": float(num_boxes.mean()),
        "solved_fraction": float(np.mean(scores >= num_boxes - 0.5)),  # solved <=> every box on a goal
        "random_goals_covered": float(random_scores.mean()),
        "random_score": float(random_scores.mean()),  # the same, under the name every environment uses
        "random_solved_fraction": float(np.mean(random_scores >= num_boxes - 0.5)),
    }


# ---------------------------------------------------------------- rendering

TILE = 32
COLOURS = {
    "wall": (92, 64, 51),
    "wall_edge": (60, 40, 32),
    "floor": (28, 28, 34),
    "goal": (220, 50, 50),
    "box": (230, 170, 40),
    "box_edge": (150, 100, 20),
    "box_on_goal": (70, 190, 90),
    "box_on_goal_edge": (30, 120, 50),
    "player": (80, 170, 255),
    "text": (240, 240, 240),
    "background": (15, 15, 20),
}
HEADER = Header(height=22, text_origin=(6, 3), font_size=14, text_colour=COLOURS["text"])


def render(state: SokobanState) -> np.ndarray:
    """One unbatched state as an RGB image: walls, floor, goals, boxes (green on a goal), player, goals covered."""
    walls, goals, boxes = (np.asarray(x, dtype=bool) for x in (state.walls, state.goals, state.boxes))
    player = tuple(np.asarray(state.player).tolist())
    covered, total = int((boxes & goals).sum()), int(boxes.sum())
    status = "  solved" if covered == total else ""
    size = ROOM_SIZE * TILE
    header_text = f"goals {covered}/{total}{status}  level {int(state.level)}"
    image, draw = canvas_with_header(size, size, COLOURS["background"], HEADER, header_text)
    for row in range(ROOM_SIZE):
        for col in range(ROOM_SIZE):
            x, y = col * TILE, HEADER.height + row * TILE
            box = (x, y, x + TILE - 1, y + TILE - 1)
            if walls[row, col]:
                draw.rectangle(box, fill=COLOURS["wall"], outline=COLOURS["wall_edge"], width=2)
                draw.line((x, y + TILE // 2, x + TILE - 1, y + TILE // 2), fill=COLOURS["wall_edge"], width=2)
                continue
            draw.rectangle(box, fill=COLOURS["floor"])
            if goals[row, col]:
                inset = 7
                draw.rectangle((x + inset, y + inset, x + TILE - 1 - inset, y + TILE - 1 - inset),
                               outline=COLOURS["goal"], width=3)
            if boxes[row, col]:
                key = "box_on_goal" if goals[row, col] else "box"
                inset = 3
                draw.rectangle((x + inset, y + inset, x + TILE - 1 - inset, y + TILE - 1 - inset),
                               fill=COLOURS[key], outline=COLOURS[key + "_edge"], width=3)
                draw.line((x + inset, y + inset, x + TILE - 1 - inset, y + TILE - 1 - inset),
                          fill=COLOURS[key + "_edge"], width=2)
                draw.line((x + inset, y + TILE - 1 - inset, x + TILE - 1 - inset, y + inset),
                          fill=COLOURS[key + "_edge"], width=2)
            if (row, col) == player:
                inset = 6
                draw.ellipse((x + inset, y + inset, x + TILE - 1 - inset, y + TILE - 1 - inset),
                             fill=COLOURS["player"])
    return np.asarray(image)


def _measure_random_agent(levels: str | None = None) -> dict[str, float]:
    """The random reference on every level of a bank once (the documented figures)."""
    env = make(levels=levels)
    codes = level_bank(levels, num_levels=1000, num_boxes=4, generator_seed=0, pull_rounds=8)  # make()'s defaults
    initial_states = jax.vmap(state_from_codes)(jnp.asarray(codes), jnp.arange(codes.shape[0]))
    return {"levels": codes.shape[0], **env.references(initial_states, np.zeros(codes.shape[0]))}


if __name__ == "__main__":
    print(_measure_random_agent(sys.argv[1] if len(sys.argv) > 1 else None))
