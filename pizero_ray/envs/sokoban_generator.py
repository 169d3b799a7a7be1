"""Procedural Sokoban levels by reverse play, in the spirit of Racaniere et al. (2017).

So that Sokoban trains with no download, a bank of 10x10 levels is generated
from a seed (pure Python, deterministic on every platform):

1. Room topology: a random walk over the 8x8 interior carves floor, stamping a
   small random pattern (bar, corner, square) at each step and turning with a
   fixed probability; the border stays wall.
2. Goals, boxes on them, and the player on distinct random floor cells.
3. Reverse play, in rounds: the player walks (shortest path, around boxes) to
   a cell beside a box from which it can pull, then pulls it 1-3 cells in a
   straight line. Boxes still on goals are pulled first, and a pull never puts
   a box on a goal. Every pull undone is a legal push, so every state reached
   is solvable from the start: the forward solution is the reverse walk
   backwards, each move negated.
4. Of the states reached with no box on a goal, the level keeps the one with
   the best score ``(1 + box switches) * total box displacement`` (after
   Racaniere et al.'s: levels where several boxes moved far and interleaved),
   and records its forward solution (a tuple of (row, column) moves; its
   length is an upper bound on the shortest solution).

Rooms where this fails (the player walled in by boxes, too cramped) are drawn
again. Banks are cached by their parameters: every environment built in a
process with the same parameters shares one.
"""

from __future__ import annotations

import functools
import random
from collections import deque
from typing import NamedTuple

import numpy as np

from pizero_ray.envs.boxoban import BOX, FLOOR, GOAL, PLAYER, PLAYER_ON_GOAL, ROOM_SIZE, WALL

MOVES = ((-1, 0), (1, 0), (0, -1), (0, 1))  # up, down, left, right: the environment's action order
MAX_BOXES = 8  # more hardly fit Boxoban-sized rooms (~31 floor cells)
MAX_ATTEMPTS_PER_LEVEL = 1000
CARVE_STEPS = 45  # rooms of ~31 floor cells, like Boxoban's (mean 31.7 on unfiltered/valid)
TURN_PROBABILITY = 0.35
MAX_PULLS_PER_ROUND = 3
# Patterns stamped around the walker (offsets from its cell): bars, corners, a square.
CARVE_PATTERNS = (
    ((0, -1), (0, 0), (0, 1)),
    ((-1, 0), (0, 0), (1, 0)),
    ((0, -1), (0, 0), (1, 0)),
    ((0, -1), (0, 0), (1, -1), (1, 0)),
    ((0, 0), (0, 1), (1, 0)),
)

Cell = tuple[int, int]


class GeneratedLevel(NamedTuple):
    codes: np.ndarray  # int8 [10, 10] tile codes (see envs.boxoban)
    solution: tuple[Cell, ...]  # forward moves that solve it, each one of MOVES


class LevelBank(NamedTuple):
    codes: np.ndarray  # int8 [L, 10, 10], read-only
    solutions: tuple[tuple[Cell, ...], ...]


def carve_room(rng: random.Random) -> set[Cell]:
    """Floor cells of a random connected room inside the border walls."""
    low, high = 1, ROOM_SIZE - 2
    row, col = rng.randint(low, high), rng.randint(low, high)
    direction = rng.choice(MOVES)
    floor: set[Cell] = set()
    for _ in range(CARVE_STEPS):
        if rng.random() < TURN_PROBABILITY:
            direction = rng.choice(MOVES)
        row = min(max(row + direction[0], low), high)
        col = min(max(col + direction[1], low), high)
        for dr, dc in rng.choice(CARVE_PATTERNS):
            # clipping keeps stamps connected to the walker's (interior) cell
            floor.add((min(max(row + dr, low), high), min(max(col + dc, low), high)))
    return floor


def _paths_from(floor: set[Cell], box_at: dict[Cell, int], start: Cell) -> dict[Cell, tuple[Cell, Cell] | None]:
    """Breadth-first search around boxes: reachable cell -> (previous cell, move), None at the start."""
    parents: dict[Cell, tuple[Cell, Cell] | None] = {start: None}
    queue = deque([start])
    while queue:
        cell = queue.popleft()
        for move in MOVES:
            nxt = (cell[0] + move[0], cell[1] + move[1])
            if nxt in floor and nxt not in box_at and nxt not in parents:
                parents[nxt] = (cell, move)
                queue.append(nxt)
    return parents


def _path_to(parents: dict[Cell, tuple[Cell, Cell] | None], cell: Cell) -> list[Cell]:
    moves = []
    while parents[cell] is not None:
        cell, move = parents[cell]
        moves.append(move)
    return moves[::-1]


def _pull_options(floor: set[Cell], box_at: dict[Cell, int], reachable: dict, boxes: list[Cell]):
    """(box, direction, cell to stand on) for every pull the player can walk to."""
    options = []
    for i, (row, col) in enumerate(boxes):
        for dr, dc in MOVES:
            stand, away = (row + dr, col + dc), (row + 2 * dr, col + 2 * dc)
            if stand in reachable and away in floor and away not in box_at:
                options.append((i, (dr, dc), stand))
    return options


def reverse_play(
    rng: random.Random, floor: set[Cell], goals: list[Cell], player: Cell, rounds: int
) -> tuple[list[Cell], Cell, list[Cell]] | None:
    """Pulls boxes off their goals; returns (boxes, player, reverse moves) of the best state, or None."""
    goal_set = set(goals)
    boxes = list(goals)  # box i starts on goal i
    box_at = {cell: i for i, cell in enumerate(boxes)}
    moves: list[Cell] = []
    last_pulled, switches = -1, 0
    best, best_score = None, 0
    for _ in range(rounds):
        reachable = _paths_from(floor, box_at, player)
        options = _pull_options(floor, box_at, reachable, boxes)
        on_goal = [option for option in options if boxes[option[0]] in goal_set]
        if not options:
            break  # walled in by boxes: a pull can only be undone by a push
        i, (dr, dc), stand = rng.choice(on_goal or options)
        moves += _path_to(reachable, stand)
        player = stand
        for _ in range(rng.randint(1, MAX_PULLS_PER_ROUND)):
            away = (player[0] + dr, player[1] + dc)
            if away not in floor or away in box_at or player in goal_set:
                break  # the box lands where the player stands: never on a goal
            del box_at[boxes[i]]
            boxes[i], box_at[player] = player, i
            player = away
            moves.append((dr, dc))
        switches += last_pulled not in (-1, i)
        last_pulled = i
        if goal_set.isdisjoint(box_at):
            displacement = sum(abs(b[0] - g[0]) + abs(b[1] - g[1]) for b, g in zip(boxes, goals))
            score = (1 + switches) * displacement  # 1 +: one-box levels have no switches
            if score > best_score:
                best, best_score = (list(boxes), player, list(moves)), score
    return best


def generate_level(rng: random.Random, num_boxes: int, pull_rounds: int) -> GeneratedLevel:
    """One solvable level with ``num_boxes`` boxes, none on a goal."""
    for _ in range(MAX_ATTEMPTS_PER_LEVEL):
        floor = carve_room(rng)
        if len(floor) < num_boxes + 2:
            continue
        cells = rng.sample(sorted(floor), num_boxes + 1)
        goals, start = cells[:num_boxes], cells[num_boxes]
        result = reverse_play(rng, floor, goals, start, pull_rounds)
        if result is None:
            continue
        boxes, player, reverse_moves = result
        codes = np.full((ROOM_SIZE, ROOM_SIZE), WALL, dtype=np.int8)
        for cell in floor:
            codes[cell] = FLOOR
        for cell in goals:
            codes[cell] = GOAL
        for cell in boxes:
            codes[cell] = BOX  # never on a goal: reverse play keeps only such states
        codes[player] = PLAYER if codes[player] == FLOOR else PLAYER_ON_GOAL
        solution = tuple((-dr, -dc) for dr, dc in reversed(reverse_moves))
        return GeneratedLevel(codes, solution)
    raise ValueError(f"could not generate a level with {num_boxes} boxes in {MAX_ATTEMPTS_PER_LEVEL} rooms")


@functools.lru_cache(maxsize=8)
def generate_levels(num_levels: int, num_boxes: int = 4, seed: int = 0, pull_rounds: int = 8) -> LevelBank:
    """A deterministic bank of ``num_levels`` levels; the first k levels do not depend on num_levels."""
    if not 1 <= num_boxes <= MAX_BOXES:
        raise ValueError(f"num_boxes must be in [1, {MAX_BOXES}], got {num_boxes}")
    rng = random.Random(seed)
    levels = [generate_level(rng, num_boxes, pull_rounds) for _ in range(num_levels)]
    codes = np.stack([level.codes for level in levels])
    codes.flags.writeable = False  # shared through the cache
    return LevelBank(codes, tuple(level.solution for level in levels))
