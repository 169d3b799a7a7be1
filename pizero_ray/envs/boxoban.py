"""Sokoban levels as arrays, and DeepMind's Boxoban text format.

A level is a 10x10 grid of tile codes (int8), one code per character of the
text format, so a bank of L levels is one compact int8 array [L, 10, 10]:

    code  char  tile
    0     ' '   floor
    1     '#'   wall
    2     '.'   goal
    3     '$'   box
    4     '*'   box on a goal
    5     '@'   player
    6     '+'   player on a goal

A Boxoban file holds levels one after another, each a header line ``; N``
followed by ten rows of ten characters and (usually) a blank line. Loading
reads one file or every ``*.txt`` under a directory (recursively, sorted), in
plain Python at environment-construction time; nothing here is traced.
Malformed input raises a one-line ValueError naming the file, the level (its
header label) and the 1-based line number in that file.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

ROOM_SIZE = 10

FLOOR, WALL, GOAL, BOX, BOX_ON_GOAL, PLAYER, PLAYER_ON_GOAL = range(7)
CHARACTERS = " #.$*@+"  # CHARACTERS[code] is the code's character
BOX_CODES = (BOX, BOX_ON_GOAL)
GOAL_CODES = (GOAL, BOX_ON_GOAL, PLAYER_ON_GOAL)
PLAYER_CODES = (PLAYER, PLAYER_ON_GOAL)

# byte -> tile code, -1 for characters that are not tiles (vectorised decoding)
_CODE_OF_BYTE = np.full(256, -1, dtype=np.int8)
for _code, _char in enumerate(CHARACTERS):
    _CODE_OF_BYTE[ord(_char)] = _code


def parse_levels(text: str, source: str = "<text>") -> np.ndarray:
    """All levels of one file's text as tile codes int8 [L, 10, 10]; ``source`` names it in errors."""
    rows: list[str] = []  # every level's rows, concatenated
    headers: list[tuple[str, int]] = []  # (label, line number of the header) per level
    level_rows = ROOM_SIZE  # rows read of the current level; "complete" before the first header
    for number, line in enumerate(text.splitlines(), start=1):
        if line.startswith(";"):
            if level_rows < ROOM_SIZE:
                _fail(source, headers[-1][0], number, f"expected {ROOM_SIZE} rows, got {level_rows}")
            headers.append((line[1:].strip() or str(len(headers)), number))
            level_rows = 0
        elif level_rows < ROOM_SIZE:
            if not line:  # a blank line ends a level; a row of floor would still be ten spaces
                _fail(source, headers[-1][0], number, f"expected {ROOM_SIZE} rows, got {level_rows}")
            if len(line) != ROOM_SIZE:
                _fail(source, headers[-1][0], number, f"expected {ROOM_SIZE} columns, got {len(line)}")
            bad = [char for char in line if char not in CHARACTERS]
            if bad:
                _fail(source, headers[-1][0], number, f"unexpected character {bad[0]!r}")
            rows.append(line)
            level_rows += 1
        elif line.strip():
            where = f"level {headers[-1][0]}, " if headers else ""
            raise ValueError(f"{source}: {where}line {number}: expected a '; N' level header, got {line[:20]!r}")
    if headers and level_rows < ROOM_SIZE:
        _fail(source, headers[-1][0], number + 1, f"expected {ROOM_SIZE} rows, got {level_rows}")
    if not headers:
        raise ValueError(f"{source}: no levels")
    codes = _CODE_OF_BYTE[np.frombuffer("".join(rows).encode("ascii"), dtype=np.uint8)]
    codes = codes.reshape(len(headers), ROOM_SIZE, ROOM_SIZE)
    problem = level_problems(codes)
    for index, message in enumerate(problem):
        if message:
            label, line_number = headers[index]
            _fail(source, label, line_number, message)
    return codes


def level_problems(codes: np.ndarray) -> list[str]:
    """Per level, why it cannot be played ('' when it can): one player, as many boxes as goals, at least one."""
    players = np.isin(codes, PLAYER_CODES).sum(axis=(1, 2))
    boxes = np.isin(codes, BOX_CODES).sum(axis=(1, 2))
    goals = np.isin(codes, GOAL_CODES).sum(axis=(1, 2))
    problems = []
    for p, b, g in zip(players.tolist(), boxes.tolist(), goals.tolist()):
        if p != 1:
            problems.append(f"expected one player, got {p}")
        elif b != g:
            problems.append(f"{b} boxes but {g} goals")
        elif b == 0:
            problems.append("no boxes")
        else:
            problems.append("")
    return problems


def _fail(source: str, label: str, line: int, message: str):
    raise ValueError(f"{source}: level {label}, line {line}: {message}")


def level_files(path: str | Path) -> list[Path]:
    """The files a levels path names: itself, or every *.txt below a directory, sorted."""
    path = Path(path)
    if not path.exists():
        raise ValueError(f"levels path {path} does not exist")
    if path.is_file():
        return [path]
    files = sorted(p for p in path.rglob("*.txt") if p.is_file())
    if not files:
        raise ValueError(f"no level files (*.txt) in {path}")
    return files


def load_levels(path: str | Path) -> np.ndarray:
    """Every level in a file or directory tree, as tile codes int8 [L, 10, 10]."""
    banks = []
    for file in level_files(path):
        try:
            text = file.read_text(encoding="ascii")
        except UnicodeDecodeError as error:
            raise ValueError(f"{file}: not an ASCII text file ({error.reason} at byte {error.start})") from None
        banks.append(parse_levels(text, str(file)))
    return np.concatenate(banks)


def format_level(codes: np.ndarray, label: str | int = 0) -> str:
    """One level back in the text format (header, rows, blank line)."""
    rows = ["".join(CHARACTERS[code] for code in row) for row in np.asarray(codes).tolist()]
    return "\n".join([f"; {label}", *rows, ""]) + "\n"
