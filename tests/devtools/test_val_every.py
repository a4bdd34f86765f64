"""tools/val_every.py: every proposal hung on validation, pick rules scored offline."""

import json

import numpy as np
import pytest

from skt_lib.geometry.objects import REFERENCE_RING_RADIUS_M
from skt_lib.learning.cloud_check import ring_placements
from tools.val_every import main, picks, score


def _skt(offset) -> np.ndarray:
    """A gently curved 6-waypoint SKT, moved by ``offset`` (m)."""
    s = np.linspace(0.0, 1.0, 6)
    return np.c_[0.1 * s, 0.02 * s * s, 0.05 - 0.03 * s] + np.asarray(offset, float)


def test_each_rule_picks_what_it_says_from_the_cloud_and_the_proposals_alone():
    base = _skt([0, 0, 0])
    centres, axes = ring_placements(base)
    # points on the ring's own tube, all along the first proposal: it cuts the cloud deepest
    side = np.cross(axes, [0.0, 0.0, 1.0])
    side /= np.linalg.norm(side, axis=1, keepdims=True)
    cloud = centres + REFERENCE_RING_RADIUS_M * side
    run = [base, _skt([0.1, 0, 0]), _skt([0.002, 0, 0])]  # 10 cm away: clear; 2 mm: cuts it too
    got, pen = picks(run, run, cloud, moved=False)
    assert got == {"first": 0, "least_penetration": 1, "medoid": 2}  # no move: no least_moved
    assert pen[0] > pen[2] >= pen[1] == 0.0
    drawn = [run[0] - [0.003, 0, 0], run[1] - [0, 0.004, 0], run[2]]  # the last was not moved
    assert picks(drawn, run, cloud, moved=True)[0]["least_moved"] == 2
    # a support where the move left every proposal where it was still gets a pick
    assert picks(run, run, cloud, moved=True)[0]["least_moved"] == 0
    with pytest.raises(ValueError, match="the same proposals"):
        picks(drawn[:2], run, cloud, moved=True)


def test_scores_are_the_picked_proposals_outcomes_and_the_bounds_contain_them():
    outcomes = {("s1", "a"): [False, True, False], ("s1", "b"): [False, True, True],
                ("s2", "a"): [True, False, False], ("s2", "b"): [False, False, False]}
    levels = {"s1": "easy", "s2": "very_hard"}
    chosen = {"first": {"s1": 0, "s2": 0}, "medoid": {"s1": 1, "s2": 1}}
    got = score(outcomes, levels, chosen, np.random.default_rng(0))
    assert got["first"]["success"]["all"] == 0.25
    assert got["first"]["success"]["easy"] == 0.0 and got["first"]["success"]["very_hard"] == 0.5
    assert got["first"]["success"]["normal"] is None
    assert got["medoid"]["success"] == pytest.approx({"all": 0.5, "easy": 1.0, "normal": None,
                                                      "hard": None, "very_hard": 0.0})
    assert got["random"]["success"]["all"] == pytest.approx(4 / 12)
    assert got["best_of_n"]["success"]["all"] == 0.75
    c = got["medoid"]["vs_first"]
    assert (c["gained"], c["lost"], c["supports_up"], c["supports_down"]) == (2, 1, 1, 1)
    lo, hi = c["difference_ci95"]
    assert -0.5 <= lo <= 0.25 <= hi <= 1.0  # the mean difference, 0.25, over two supports
    assert "vs_first" not in got["first"]


def test_first_and_best_of_n_are_val_sims_rows_pair_for_pair(tiny_evaluated, tmp_path):
    """The same generator and the same move as tools/val_sim.py: its one-SKT row is the
    'first' rule here and its best of N the bound, on every pair."""
    from tools import val_sim

    params, data, _, _ = tiny_evaluated
    every, rows = tmp_path / "every.json", tmp_path / "val_sim.json"
    assert main(["--params", str(params), "--data-root", str(data), "--out", str(every)]) == 0
    assert val_sim.main(["--params", str(params), "--data-root", str(data), "--methods",
                         "skt_flow", "--out", str(rows)]) == 0
    got, ref = json.loads(every.read_text()), json.loads(rows.read_text())
    # every one of skt_flow's flow_samples samples, in its read-out's order: val_sim's
    # proposals are the first n_proposals of them
    assert got["moved_clear"] is True and got["n_proposals"] == 5 and ref["skt_flow_samples"] == 5
    assert set(got["outcomes"]) == set(ref["outcomes"]["skt_flow"]) and got["outcomes"]
    assert all(len(v) == 5 for v in got["outcomes"].values())
    assert {k: v[0] for k, v in got["outcomes"].items()} == ref["outcomes"]["skt_flow@1"]
    assert {k: any(v[:3]) for k, v in got["outcomes"].items()} == ref["outcomes"]["skt_flow"]
    assert got["rules"]["first"]["success"] == ref["methods"]["skt_flow@1"]["success"]
    assert set(got["picks"]) == {"first", "least_penetration", "least_moved", "medoid",
                                 "cloud_check", "probes_held_out"}
    # the tiny set's objects hang or fail with their support whichever SKT runs, so the SKTs
    # themselves are compared: val_sim's draws of skt_flow (its generator), each moved clear
    from skt_lib.config.params_file import load_params
    from skt_lib.eval.methods import load_models, make_method
    from skt_lib.eval.probe_check import load_probes
    from skt_lib.learning.cloud_check import ring_penetrations
    from skt_lib.seeding import item_rng

    prm = load_params(params)
    p, T, seed = prm.sim_eval, prm.clustering.T, prm.common.seed
    assert p.flow_contacts > 1  # sim_eval's contact hypotheses, which val_every must follow
    supports, _, _ = val_sim.validation_set(data, T, seed, p)
    model, probes = load_models(data, ["skt_flow"], T)["skt_flow"], load_probes(data)
    for s in supports:
        made = make_method("skt_flow", model, s.gt, np.asarray(p.kpam_pre_hang_m), p.kpam_lift_m,
                           rng=item_rng(seed, "val_sim/skt_flow", s.support_id), n_proposals=5,
                           flow_contacts=p.flow_contacts, probes=probes, flow_samples=5)
        pen = ring_penetrations([k.positions for k in made.propose(s.cloud)], s.cloud) * 1e6
        assert got["penetration_mm2"][s.support_id] == pytest.approx(pen.tolist(), abs=1e-9)
