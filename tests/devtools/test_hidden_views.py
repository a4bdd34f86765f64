"""tools/hidden_views.py: which views show none of a support's link to the wall, and how the
methods fare on the supports whose evaluated view is one of them."""

import json

import numpy as np
import pandas as pd
import pytest

from tools.hidden_views import BAND_M, MIN_POINTS, band_counts, by_method, evaluated_view, main


def test_only_points_strictly_inside_the_band_count():
    lo, hi = BAND_M
    view_a = np.array([[lo + 1e-4, 0, 0], [hi - 1e-4, 0, 0], [(lo + hi) / 2, 0.1, -0.2],
                       [lo, 0, 0], [hi, 0, 0], [0.005, 0, 0], [0.1, 0, 0]])
    view_b = np.array([[0.1, 0, 0]] * 7)
    assert band_counts(np.stack([view_a, view_b])).tolist() == [3, 0]


def test_success_is_split_by_the_supports_whose_evaluated_view_hides():
    trials = pd.DataFrame({
        "method": ["m"] * 5 + ["p"] * 3,
        "support_id": ["a", "a", "b", "b", "b", "a", "a", "b"],
        "success": [False, True, True, True, False, True, True, False],
        "proposal": [None, None, None, None, None, 0, 1, 0]})  # p's proposal 1 is not a row
    got = by_method(trials, {"a"})
    assert got["m"] == {"hiding_pairs": 2, "hiding_success": 0.5,
                        "other_pairs": 3, "other_success": pytest.approx(2 / 3)}
    assert got["p"] == {"hiding_pairs": 1, "hiding_success": 1.0,
                        "other_pairs": 1, "other_success": 0.0}


def test_the_survey_takes_the_view_the_methods_were_given(tiny_evaluated, tmp_path):
    from skt_lib.config.params_file import load_params
    from skt_lib.eval.protocol import load_test_set

    params, data, sim_eval, _ = tiny_evaluated
    p = load_params(params)
    test, _, _ = load_test_set(data, p.clustering.T, p.common.seed, p.sim_eval.grasp_pitch_deg)
    n_views = {s.support_id: len(np.load(data / "render_views" / f"{s.support_id}.npz")["points"])
               for s in test}
    assert test and all(evaluated_view(p.common.seed, s.support_id, n_views[s.support_id]) == s.view
                        for s in test)
    out = tmp_path / "rep"
    assert main(["--params", str(params), "--data-root", str(data),
                 "--trials", str(sim_eval / "trials.parquet"), "--out", str(out)]) == 0
    got = json.loads((out / "hidden_views.json").read_text())
    trials = pd.read_parquet(sim_eval / "trials.parquet")
    hiding = set(got["splits"]["test"]["evaluated_hiding"])
    for s in test:  # a support is listed exactly when its evaluated view shows under MIN_POINTS
        counts = band_counts(np.load(data / "render_views" / f"{s.support_id}.npz")["points"])
        assert (s.support_id in hiding) == (counts[s.view] < MIN_POINTS)
    first = trials[trials["proposal"].fillna(0) == 0]
    for m, v in got["methods"].items():
        assert v["hiding_pairs"] + v["other_pairs"] == int((first["method"] == m).sum())
    assert "| test |" in (out / "hidden_views.md").read_text()
