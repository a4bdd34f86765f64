"""tools/template_reach.py: the gap between a support's SKTs and the family templates, and
the whole run on the tiny pipeline's artifacts."""

import json

import numpy as np
import pytest

from tools.template_reach import gap_to_templates, main, retrieve


def test_the_gap_is_the_nearest_skts_mean_waypoint_distance_relative_to_its_xi0():
    rng = np.random.default_rng(0)
    template = np.cumsum(rng.normal(0, 0.01, (2, 40, 3)), axis=1)
    template -= template[:, :1]  # templates are stored relative to ξ_0
    far = template[0] + [0.3, -0.2, 0.1]  # template 0 placed elsewhere: no gap to it
    near = template[1] + [0.0, 0.0, 0.004] * (np.arange(40) > 0)[:, None]  # 4 mm off but ξ_0
    gaps = gap_to_templates(np.stack([far, near]), template)
    assert gaps[0] == pytest.approx(0.0, abs=1e-9)
    assert gaps[1] == pytest.approx(4.0 * 39 / 40)


def test_retrieval_takes_the_key_of_nearest_direction_not_length():
    keys = np.array([[1.0, 0.0, 0.0], [0.0, 3.0, 0.0], [0.6, 0.8, 0.0]])
    assert retrieve(keys, np.array([0.0, 0.1, 0.0])) == 1  # far in length, same direction
    assert retrieve(keys, np.array([5.0, 0.2, 0.0])) == 0
    assert retrieve(keys, np.array([0.5, 0.9, 0.0])) == 2


def test_the_report_on_the_tiny_pipeline(tiny_dataset, tmp_path):
    params, data, _ = tiny_dataset
    assert main(["--params", str(params), "--data-root", str(data), "--out", str(tmp_path)]) == 0
    d = json.loads((tmp_path / "template_reach.json").read_text())
    k = str(d["k"])
    assert k in d["labels"] and sum(d["labels"][k]["family_sizes"]) > 0
    model = d["model"]["all"]
    assert model["n_views"] > 0 and model["template_mm"] > 0 and model["offset_mm"] >= 0
    for r in d["model"].values():  # the best of the retrieved support's SKTs, view by view
        assert 0 <= r["retrieved_best_mm"] <= r["retrieved_mm"]
    assert (tmp_path / "template_reach.png").stat().st_size > 10_000
    assert f"![{d['picture']}](template_reach.png)" in (tmp_path / "template_reach.md").read_text()
