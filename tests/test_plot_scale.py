"""scripts/plot_scale.py: the scale model's figures show the measured lines and the model's."""

import json

import pytest

from tests.figures import assert_curves_drawn
from tests.scripts_loading import load_script


@pytest.fixture(scope="module")
def script():
    return load_script("plot_scale")


def _measured(design, workers, chunks, driver_s):
    return {"source": "measured", "design": design, "workers": workers, "chunks": chunks, "driver_s": driver_s,
            "stand_ins": workers > 16}


def _model(design, pairs, parameters, efficiency):
    return {"source": "model", "design": design, "workers": 512, "pairs_per_chunk": pairs, "parameters": parameters,
            "efficiency": efficiency}


def test_both_figures_draw_every_line(script, tmp_path):
    rows = [_measured(design, workers, chunks, chunks * 1e-3 * (1 + workers / 1000))
            for design in ("a_parts_on_driver", "a_parts_on_workers") for workers in (1, 512) for chunks in (64, 512)]
    rows += [_model(design, pairs, d, eff / d ** 0.3) for design, eff in (("a_node_sums", 1.0), ("b_replayed", 0.01))
             for pairs in (1024, 32768) for d in (54_279, 10**6, 10**8)]
    result = tmp_path / "scale.json"
    result.write_text(json.dumps({"rows": rows}))
    assert script.main([str(result), "--out", str(tmp_path / "scale")]) == 0
    assert_curves_drawn(tmp_path / "scale_measured.png", size=(1210, 440), panels=[("C0", "C1")] * 2)
    assert_curves_drawn(tmp_path / "scale_model.png", size=(1210, 440), panels=[("C0", "C1")] * 2)
