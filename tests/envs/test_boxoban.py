"""Sokoban levels: the Boxoban text-format loader and the reverse-play generator."""

from collections import deque
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from pizero_ray.envs import boxoban, sokoban, sokoban_generator

# The real Boxoban files live beside the repository (never copied into it).
BOXOBAN = Path(__file__).parents[3] / "shared" / "boxoban"

LEVEL = """\
##########
#   ######
# $ ###  #
#.  .  $ #
# #  # # #
#  $ $.  #
#   +   ##
# .#######
#$########
##########"""


def _file(tmp_path: Path, text: str, name: str = "000.txt") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def _levels_text(count: int, first: int = 0) -> str:
    return "".join(f"; {i}\n{LEVEL}\n\n" for i in range(first, first + count))


# ---------------------------------------------------------------- the loader


def _assert_boxoban_levels(codes: np.ndarray):
    assert codes.dtype == np.int8 and codes.shape[1:] == (10, 10)
    assert np.all(np.isin(codes, boxoban.PLAYER_CODES).sum(axis=(1, 2)) == 1)
    assert np.all(np.isin(codes, boxoban.BOX_CODES).sum(axis=(1, 2)) == 4)
    assert np.all(np.isin(codes, boxoban.GOAL_CODES).sum(axis=(1, 2)) == 4)
    assert np.all(codes[:, 0, :] == boxoban.WALL) and np.all(codes[:, :, -1] == boxoban.WALL)


@pytest.mark.parametrize("split", ["unfiltered/valid", "medium/valid", "unfiltered/train"])
def test_real_boxoban_splits_load(split):
    path = BOXOBAN / split
    if not path.is_dir():
        pytest.skip(f"Boxoban files not found at {path}")
    codes = boxoban.load_levels(path)
    assert len(codes) == 1000 * len(list(path.glob("*.txt")))  # a thousand levels a file
    _assert_boxoban_levels(codes)


def test_a_single_real_file_loads_and_round_trips():
    path = BOXOBAN / "medium" / "valid" / "000.txt"
    if not path.is_file():
        pytest.skip(f"Boxoban file not found at {path}")
    codes = boxoban.load_levels(path)
    assert codes.shape == (1000, 10, 10)
    text = path.read_text()
    assert boxoban.format_level(codes[0], 0) == text[: text.index("; 1")]


def test_directories_are_read_recursively_in_order(tmp_path):
    _file(tmp_path, _levels_text(2), "b.txt")
    (tmp_path / "sub").mkdir()
    _file(tmp_path / "sub", _levels_text(3), "a.txt")
    _file(tmp_path, "not levels", "notes.md")
    codes = boxoban.load_levels(tmp_path)
    assert codes.shape == (5, 10, 10)
    assert boxoban.level_files(tmp_path) == [tmp_path / "b.txt", tmp_path / "sub" / "a.txt"]


def test_box_and_player_on_goal_and_windows_line_ends(tmp_path):
    text = _levels_text(1).replace("$.  #\n#   +", "*.  #\n#   @").replace("\n", "\r\n")
    codes = boxoban.load_levels(_file(tmp_path, text))
    assert codes[0, 5, 5] == boxoban.BOX_ON_GOAL and codes[0, 6, 4] == boxoban.PLAYER
    state = sokoban.state_from_codes(codes[0])
    assert bool(state.goals[5, 5]) and bool(state.boxes[5, 5]) and int(sokoban.covered_goals(state)) == 1
    assert tuple(np.asarray(state.player).tolist()) == (6, 4)


def test_a_level_is_decoded_into_its_planes():
    state = sokoban.state_from_codes(boxoban.parse_levels("; 0\n" + LEVEL + "\n")[0])
    assert tuple(np.asarray(state.player).tolist()) == (6, 4)
    assert bool(state.goals[6, 4]) and not bool(state.walls[6, 4])  # '+': player on a goal
    assert sorted(map(tuple, np.argwhere(np.asarray(state.boxes)).tolist())) == [(2, 2), (3, 7), (5, 3), (5, 5), (8, 1)]
    assert int(np.asarray(state.goals).sum()) == 5 and int(np.asarray(state.walls).sum()) == 61


@pytest.mark.parametrize(
    "edit, message",
    [
        # level 12 starts on line 145 of the file (12 lines a level); its 5th row is line 150
        (lambda lines: lines.__setitem__(149, lines[149][:9]), "level 12, line 150: expected 10 columns, got 9"),
        (lambda lines: lines.__setitem__(149, lines[149] + "#"), "level 12, line 150: expected 10 columns, got 11"),
        (lambda lines: lines.__setitem__(149, "#  x $.  #"), "level 12, line 150: unexpected character 'x'"),
        (lambda lines: lines.__delitem__(149), "level 12, line 155: expected 10 rows, got 9"),
        (lambda lines: lines.__setitem__(152, "#@.#######"), "level 12, line 145: expected one player, got 2"),
        (lambda lines: lines.__setitem__(153, "# ########"), "level 12, line 145: 4 boxes but 5 goals"),
        (lambda lines: lines.__setitem__(155, "not a header"), "level 12, line 156: expected a '; N' level header"),
    ],
)
def test_malformed_files_name_the_file_the_level_and_the_line(tmp_path, edit, message):
    lines = _levels_text(20).split("\n")
    assert lines[144] == "; 12" and lines[149] == LEVEL.split("\n")[4]
    edit(lines)
    path = _file(tmp_path, "\n".join(lines))
    with pytest.raises(ValueError) as error:
        boxoban.load_levels(tmp_path)
    assert str(error.value).startswith(f"{path}: ")
    assert str(error.value) == f"{path}: {message}" or str(error.value).startswith(f"{path}: {message}")
    assert "\n" not in str(error.value)


def test_exact_error_for_a_short_row(tmp_path):
    lines = _levels_text(20).split("\n")
    lines[149] = lines[149][:9]
    path = _file(tmp_path, "\n".join(lines))
    with pytest.raises(ValueError) as error:
        boxoban.load_levels(path)
    assert str(error.value) == f"{path}: level 12, line 150: expected 10 columns, got 9"


def test_truncated_last_level_and_empty_files(tmp_path):
    path = _file(tmp_path, _levels_text(2)[: -len("#$########\n##########\n\n")])  # two rows short
    with pytest.raises(ValueError, match="level 1, line 22: expected 10 rows, got 8"):
        boxoban.load_levels(path)
    empty = _file(tmp_path, "\n", "empty.txt")
    with pytest.raises(ValueError, match="empty.txt: no levels"):
        boxoban.load_levels(empty)


def test_missing_paths_and_empty_directories(tmp_path):
    with pytest.raises(ValueError, match="does not exist"):
        boxoban.load_levels(tmp_path / "missing")
    with pytest.raises(ValueError, match="no level files"):
        boxoban.load_levels(tmp_path)


# ---------------------------------------------------------------- the generator


@pytest.fixture(scope="module")
def bank():
    return sokoban_generator.generate_levels(200, num_boxes=4, seed=3)


def test_generated_levels_have_the_requested_boxes_and_goals(bank):
    codes = bank.codes
    assert codes.shape == (200, 10, 10) and codes.dtype == np.int8
    _assert_boxoban_levels(codes)
    assert not np.any(codes == boxoban.BOX_ON_GOAL)  # no box starts on a goal
    assert np.all(codes[:, [0, -1], :] == boxoban.WALL) and np.all(codes[:, :, [0, -1]] == boxoban.WALL)
    assert all(not problem for problem in boxoban.level_problems(codes))
    two = sokoban_generator.generate_levels(20, num_boxes=2, seed=3).codes
    assert np.all(np.isin(two, boxoban.BOX_CODES).sum(axis=(1, 2)) == 2)


def test_generation_is_deterministic_given_the_seed(bank):
    again = sokoban_generator.generate_levels.__wrapped__(200, num_boxes=4, seed=3)
    np.testing.assert_array_equal(again.codes, bank.codes)
    assert again.solutions == bank.solutions
    prefix = sokoban_generator.generate_levels.__wrapped__(10, num_boxes=4, seed=3)
    np.testing.assert_array_equal(prefix.codes, bank.codes[:10])
    other = sokoban_generator.generate_levels(10, num_boxes=4, seed=4)
    assert not np.array_equal(other.codes, bank.codes[:10])
    assert len({level.tobytes() for level in bank.codes}) > 190  # varied, not one room over and over


def test_recorded_solutions_solve_their_levels_in_the_environment(bank):
    """Replays each level's forward solution (the reverse play undone) through the JAX rules."""
    action_of = {tuple(move): action for action, move in enumerate(sokoban.MOVES.tolist())}
    num = 40
    length = max(len(solution) for solution in bank.solutions[:num])
    # padded with repeats of the last move: what follows the end of an episode does not count
    actions = np.array([[action_of[m] for m in s] + [action_of[s[-1]]] * (length - len(s))
                        for s in bank.solutions[:num]], dtype=np.int32)
    env = sokoban.make(horizon=length + 1, num_levels=1)  # rules only: states come from the bank

    @jax.jit
    def replay(codes, actions):
        def one(codes, actions):
            state = sokoban.state_from_codes(codes)

            def body(carry, action):
                state, done, score = carry
                state, _, reward, step_done = env.step(state, action)
                return (state, done | step_done, score + jnp.where(done, 0.0, reward)), None

            (_, done, score), _ = jax.lax.scan(body, (state, False, 0.0), actions)
            return done, score

        return jax.vmap(one)(codes, actions)

    # the horizon is past the longest solution: an episode that ended was solved, its score 4 goals
    done, score = replay(jnp.asarray(bank.codes[:num]), jnp.asarray(actions))
    assert np.all(np.asarray(done))
    np.testing.assert_array_equal(np.asarray(score), 4.0)


def _bfs_solution_length(codes: np.ndarray, limit: int = 200_000) -> int | None:
    """Shortest solution by plain breadth-first search (an independent check; small levels only)."""
    walls = codes == boxoban.WALL
    goals = frozenset(map(tuple, np.argwhere(np.isin(codes, boxoban.GOAL_CODES)).tolist()))
    boxes = frozenset(map(tuple, np.argwhere(np.isin(codes, boxoban.BOX_CODES)).tolist()))
    player = tuple(np.argwhere(np.isin(codes, boxoban.PLAYER_CODES))[0].tolist())
    start = (player, boxes)
    seen, queue = {start}, deque([(start, 0)])
    while queue and len(seen) < limit:
        (player, boxes), depth = queue.popleft()
        if boxes == goals:
            return depth
        for dr, dc in sokoban_generator.MOVES:
            target = (player[0] + dr, player[1] + dc)
            if walls[target]:
                continue
            if target in boxes:
                beyond = (target[0] + dr, target[1] + dc)
                if walls[beyond] or beyond in boxes:
                    continue
                next_state = (target, boxes - {target} | {beyond})
            else:
                next_state = (target, boxes)
            if next_state not in seen:
                seen.add(next_state)
                queue.append((next_state, depth + 1))
    return None


@pytest.mark.parametrize("num_boxes", [1, 2])
def test_small_generated_levels_are_solvable_by_search(num_boxes):
    bank = sokoban_generator.generate_levels(4, num_boxes=num_boxes, seed=7)
    for codes, solution in zip(bank.codes, bank.solutions):
        assert np.isin(codes, boxoban.BOX_CODES).sum() == num_boxes
        shortest = _bfs_solution_length(codes)
        assert shortest is not None and 0 < shortest <= len(solution)


def test_the_environment_samples_from_the_generated_bank():
    env = sokoban.make(num_levels=30, generator_seed=3)
    states, _ = jax.jit(jax.vmap(env.reset))(jax.random.split(jax.random.PRNGKey(0), 16))
    codes = sokoban_generator.generate_levels(30, 4, 3).codes
    for e in range(3):
        expected = sokoban.state_from_codes(codes[int(states.level[e])])
        np.testing.assert_array_equal(states.boxes[e], expected.boxes)
        np.testing.assert_array_equal(states.player[e], expected.player)
