"""`pizero render` and the states figure: legible, captioned frames whose score is the evaluated episode's.

The runs are untrained (a config and no checkpoint: the initial parameters),
with the cheapest agent to compile; nothing is trained here.
"""

import numpy as np
import pytest
from PIL import Image

from pizero_ray.cli import caption, main, render, states
from pizero_ray.config import ConfigError, build_config
from pizero_ray.evaluation.runs import evaluate_run
from pizero_ray.storage import run_dir


@pytest.fixture(scope="module")
def runs(tmp_path_factory):
    """env name -> an untrained run dir."""
    root = tmp_path_factory.mktemp("runs")
    paths = {}
    for env in ("tsp", "collect"):
        paths[env] = root / env
        run_dir.write_config(paths[env], build_config("tiny", env=env, planner="none"))
    return paths


def test_legible_scales_small_frames_crisply_and_big_ones_smoothly():
    small = np.zeros((80, 100, 3), np.uint8)
    small[:40] = 255
    crisp = caption.legible(small)
    assert crisp.shape == (400, 500, 3) and set(np.unique(crisp)) == {0, 255}  # x5, no blended pixels
    assert caption.legible(np.zeros((394, 336, 3), np.uint8)).shape == (640, 546, 3)  # x2 would be 788
    assert caption.legible(np.zeros((560, 560, 3), np.uint8)).shape == (560, 560, 3)


def test_annotate_keeps_the_frame_and_adds_a_strip_of_text():
    frame = np.full((500, 500, 3), 255, np.uint8)
    one, two = caption.annotate(frame, ["first"]), caption.annotate(frame, ["first", "second"])
    assert (one[:500] == frame).all() and 500 < one.shape[0] < two.shape[0]
    assert (one[500:] == caption.CAPTION_TEXT).all(-1).any()  # the text is drawn
    long_line = "a caption far too long for the frame " * 6
    assert caption.annotate(frame, [long_line]).shape == one.shape  # a smaller font, the same strip


def test_measures_of_the_environments_scored_at_the_end():
    from pizero_ray.envs.flp import FLPState
    from pizero_ray.envs.tsp import TSPState

    clients = np.array([[0.0, 0.0], [0.0, 0.4], [1.0, 1.0]])
    facilities = np.array([[0.0, 0.1], [1.0, 0.9]])
    placed = lambda t: FLPState(clients, facilities, t)
    assert caption.measures("flp", placed(0), final=False) == ["covering radius: no facility yet"]
    assert caption.measures("flp", placed(2), final=True) == ["covering radius 0.300"]
    assert caption.measures("flp-mean", placed(2), final=True) == ["mean distance 0.167"]
    line = np.stack([np.linspace(0, 1, 13), np.zeros(13)], axis=-1)  # past Held-Karp's 12 cities
    assert caption.measures("tsp", TSPState(line, np.arange(13), 13), final=True) == [
        "tour length 2.000  ·  nearest neighbour 2.000"]
    assert caption.measures("collect", None, final=True) == []


def test_render_png_is_legible_and_captioned(runs, tmp_path):
    png = tmp_path / "final.png"
    assert main(["render", str(runs["tsp"]), "--out", str(png), "--seed", "3"]) == 0
    drawn = np.asarray(Image.open(png).convert("RGB"))
    played = render.play(runs["tsp"], episodes=1, seed=3)
    bare = caption.legible(played.env.render(played.episodes[0][-1].state))
    assert caption.LEGIBLE[0] <= max(bare.shape[:2]) <= caption.LEGIBLE[1]
    assert drawn.shape[1] == bare.shape[1] and drawn.shape[0] > bare.shape[0]  # the caption strip below
    assert (drawn[:bare.shape[0]] == bare).all()  # the final state, unchanged above it
    assert (drawn[bare.shape[0]:] == caption.CAPTION_TEXT).all(-1).sum() > 100


def test_the_caption_says_the_evaluated_episodes_score_and_tour_lengths(runs):
    from pizero_ray.envs import tsp

    played = render.play(runs["tsp"], episodes=1, seed=3)
    shots = played.episodes[0]
    evaluated = evaluate_run(runs["tsp"], episodes=1, seed=3)["mean_score"]
    assert [shot.step for shot in shots] == list(range(11)) and [shot.final for shot in shots] == [False] * 10 + [True]
    assert shots[-1].score == pytest.approx(evaluated, rel=1e-6)
    head, lengths = render.shot_caption(played.env, shots[-1])
    assert head == f"TSP  ·  step 10/10  ·  score {evaluated:.3f}"
    optimal = float(tsp.optimal_tour_length(np.asarray(shots[-1].state.coordinates)))
    assert lengths.startswith(f"tour length {-evaluated:.3f}  ·  optimal {optimal:.3f} (+")
    so_far = tsp.placed_path_length(shots[4].state)
    assert render.shot_caption(played.env, shots[4]) == ["TSP  ·  step 4/10  ·  score 0",
                                                         f"tour length so far {so_far:.3f}"]


def test_every_gif_frame_is_captioned_at_one_size(runs, tmp_path):
    gif = tmp_path / "episode.gif"
    assert main(["render", str(runs["collect"]), "--out", str(gif)]) == 0
    with Image.open(gif) as image:
        assert image.n_frames == 21 and max(image.size) >= caption.LEGIBLE[0]  # the initial state and 20 steps
        sizes = set()
        for index in range(image.n_frames):
            image.seek(index)
            sizes.add(image.size)
        assert len(sizes) == 1


def test_states_figure_draws_one_panel_per_environment(runs, tmp_path):
    out = states.states_figure(runs, tmp_path / "figs" / "states.png", seed=1)
    with Image.open(out) as image:
        width, height = image.size
        untitled = np.asarray(image.convert("L"))
    inches = states.PANEL_INCHES
    assert (width, height) == (round(2 * inches[0] * states.DPI), round(inches[1] * states.DPI))  # 1 row, 2 panels
    titled = states.states_figure(runs, tmp_path / "figs" / "titled.png", seed=1, title="after 3 training minutes")
    with Image.open(titled) as image:
        assert image.size == (width, height)  # the title takes room inside the same size
        band = np.asarray(image.convert("L"))[: round(0.12 * states.DPI)]
    assert band.min() < 128 and untitled[: round(0.12 * states.DPI)].min() > 128  # ink only where a title is
    panel = states.final_state_panel("collect", runs["collect"], seed=1)
    evaluated = evaluate_run(runs["collect"], episodes=1, seed=1)["mean_score"]
    assert panel.title == "Collect" and panel.notes == [f"score {caption.format_score(evaluated)}"]


@pytest.mark.parametrize("count, shape", [(1, (1, 1)), (2, (1, 2)), (3, (1, 3)), (4, (2, 2)), (5, (2, 3)), (6, (2, 3))])
def test_grid_shape(count, shape):
    assert states.grid_shape(count) == shape


def test_states_figure_bad_inputs_are_one_line_errors(runs, tmp_path):
    cases = [
        ({f"env{i}": runs["tsp"] for i in range(7)}, "states.png", "takes 1..6 environments, got 7"),
        ({}, "states.png", "got 0"),
        ({"tsp": runs["collect"]}, "states.png", f"run dir {runs['collect']} is a 'collect' run, not 'tsp'"),
        ({"tsp": tmp_path / "nowhere"}, "states.png", "nowhere does not exist"),
        ({"tsp": runs["tsp"]}, "states.pdf", "the states figure is a .png, got"),
    ]
    for run_paths, name, message in cases:
        with pytest.raises(ConfigError, match=message) as error:
            states.states_figure(run_paths, tmp_path / name)
        assert "\n" not in str(error.value)
    assert not list(tmp_path.glob("states.*"))
