"""Every method through the same commands: train, resume, eval, inspect, render; --help names the methods."""

import json

import pytest

from pizero_ray.cli import main
from pizero_ray.storage import run_dir as rundir
from tests.figures import colour_pixels, read_rgb

TINY_BASELINE = ["--preset", "tiny", "--selfplay-episodes", "4", "--batch-size", "16", "--replay-size", "8",
                 "--updates-per-iteration", "2", "--no-progress", "--checkpoint-every", "1"]


def scalars(run) -> dict[str, list[int]]:
    """Tag -> steps of the scalars in a run's TensorBoard event files (TFRecord framing, Event protos)."""
    import struct

    from tensorboardX.proto.event_pb2 import Event

    found: dict[str, list[int]] = {}
    for path in sorted((run / "tensorboard").iterdir()):
        data = path.read_bytes()
        while data:
            (length,) = struct.unpack("<Q", data[:8])
            event = Event.FromString(data[12:12 + length])
            data = data[12 + length + 4:]
            for value in event.summary.value:
                found.setdefault(value.tag, []).append(event.step)
    return found


def _json_line(out: str) -> dict:
    return json.loads(out.strip().splitlines()[-1])


def test_train_help_names_every_method(capsys):
    with pytest.raises(SystemExit):
        main(["train", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "--method" in text and "(one of pizero, es, alphazero, muzero)" in text


def test_a_baseline_trains_resumes_and_is_evaluated_rendered_and_inspected(tmp_path, capsys):
    """AlphaZero on FLP: the simulator's search in self-play and in eval, over the grid of actions.

    (Each command compiles its own programs, about 20 s each here; MuZero's learner is checked for
    resume in tests/baselines/test_learner.py, and it acts through the same commands.)"""
    method, run = "alphazero", tmp_path / "run"
    args = ["--method", method, "--env", "flp", *TINY_BASELINE]
    curve = ["--eval-every", "3", "--eval-episodes", "2"]
    assert main(["train", "--run-dir", str(run), "--iterations", "2", *args, *curve]) == 0
    first = _json_line(capsys.readouterr().out)
    assert first["iteration"] == 2 and first["workers_killed"] == 0
    assert main(["resume", str(run), "--iterations", "3", "--no-progress"]) == 0
    assert _json_line(capsys.readouterr().out)["iteration"] == 3
    rows = rundir.read_metrics(run)
    assert [row["iteration"] for row in rows] == [0, 1, 2, 3]  # the untrained agent's evaluation first
    assert "eval_mean_score" in rows[3]  # the resume kept --eval-every 3
    rows = rows[1:]
    assert {"mean_score", "loss", "policy_loss", "value_loss", "wall_time_s"} <= set(rows[-1])
    assert rows[2]["wall_time_s"] >= rows[1]["wall_time_s"] > 0  # training time carries on across the resume
    events = scalars(run)  # TensorBoard mirrors the metrics, across the resume too
    assert sorted(events["pizero/mean_score"]) == [1, 2, 3] and sorted(events["pizero/policy_loss"]) == [1, 2, 3]

    assert main(["eval", str(run), "--episodes", "3", "--json"]) == 0
    result = _json_line(capsys.readouterr().out)
    assert (result["method"], result["iteration"], result["episodes"]) == (method, 3, 3)
    assert main(["inspect", str(run), "--json"]) == 0
    inspected = _json_line(capsys.readouterr().out)
    assert inspected["method"] == method and inspected["checkpoints"][-1] == 3
    out = tmp_path / "episode.png"
    assert main(["render", str(run), "--out", str(out)]) == 0
    _assert_final_flp_frame(out)


def _assert_final_flp_frame(png):
    """``pizero render``'s PNG of an FLP episode: the final placement drawn, and its caption below it."""
    from pizero_ray.cli import caption
    from pizero_ray.envs import flp

    image = read_rgb(png)
    drawing, strip = image[:flp.SIZE], image[flp.SIZE:]
    # FLP's square drawing, kept at its size (legible already), over a caption strip of two lines: 64 pixels
    assert image.shape[:2] == (flp.SIZE + 64, flp.SIZE)
    # The episode has ended: every facility is placed, each a square of 19 x 19 pixels drawn over the rest
    # (one square at least: two may overlap), and the clients as dots, each with a link to its facility.
    assert colour_pixels(drawing, flp.FACILITY_COLOUR) >= 19 * 19
    assert colour_pixels(drawing, flp.CLIENT_COLOUR) >= 50
    assert colour_pixels(drawing, flp.LINK_COLOUR) >= 50
    assert colour_pixels(strip, caption.CAPTION_TEXT) >= 100  # the caption's text
