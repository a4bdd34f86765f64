"""tools/sctdn_sweeps.py: where along a sweep an object cuts deepest, what counts as clear,
and the whole run on the tiny pipeline's artifacts."""

import json

import numpy as np
import pytest

from stages.rrt_skts import SWEEP_TOL_M
from tools.sctdn_sweeps import clear, deepest, main, summary


def test_deepest_is_the_least_clearance_and_its_share_of_the_path():
    per_pose = np.array([0.004, 0.001, -0.002, -0.005, 0.0])  # the far end first, the hang last
    assert deepest(per_pose) == (-0.005, 0.75)
    assert deepest(np.array([-0.001])) == (-0.001, 0.0)
    with pytest.raises(ValueError, match="empty"):
        deepest(np.array([]))


def test_a_sweep_is_clear_within_the_stages_tolerance_and_not_beyond():
    tol_mm = 1000 * SWEEP_TOL_M
    assert clear({"clearance_mm": -tol_mm + 0.01})
    assert not clear({"clearance_mm": -tol_mm - 0.01})


def test_the_summary_counts_clear_sweeps_and_where_the_others_cut():
    row = lambda c, at: {"clearance_mm": c, "deepest_at": at}  # noqa: E731
    results = [{"sweeps": {"stored": [row(1.0, 0.2), row(-5.0, 0.9)],
                           "sctdn": [row(-6.0, 0.1), row(-7.0, 0.6)]}}]
    s = summary(results)
    assert s["stored"]["clear_rate"] == 0.5 and s["sctdn"]["clear_rate"] == 0.0
    assert (s["sctdn"]["failing_deepest_in_first_half"],
            s["sctdn"]["failing_deepest_in_second_half"]) == (1, 1)
    assert s["stored"]["failing_deepest_in_second_half"] == 1
    assert s["sctdn"]["clearance_mm_median"] == -6.5


def test_the_report_on_the_tiny_pipeline(tiny_dataset, tmp_path, capsys):
    params, data, _ = tiny_dataset
    codes = {}
    for level in ("easy", "normal", "hard", "very_hard"):
        out = tmp_path / level
        codes[level] = main(["--params", str(params), "--data-root", str(data),
                             "--level", level, "--out", str(out)])
    assert set(codes.values()) <= {0, 2} and 0 in codes.values()
    if 2 in codes.values():  # a level with no validation support that has an SKT says so
        assert "no validation support of level" in capsys.readouterr().err
    level = next(k for k, v in codes.items() if v == 0)
    d = json.loads((tmp_path / level / "sctdn_sweeps.json").read_text())
    n = d["n_supports"] * d["n_objects"]
    assert n > 0 and all(d["summary"][k]["n_sweeps"] == n for k in ("stored", "sctdn"))
    for r in d["supports"]:
        for rows in r["sweeps"].values():
            assert all(0.0 <= x["deepest_at"] <= 1.0 and len(x["keypoint"]) == 3 for x in rows)
    assert (tmp_path / level / "sctdn_sweeps.png").stat().st_size > 10_000
    md = (tmp_path / level / "sctdn_sweeps.md").read_text()
    assert "![every support of the level from the side](sctdn_sweeps.png)" in md
    assert all(r["support_id"] in md for r in d["supports"])
