"""skt_flow's read-out order: the training objects carried along each sample as executed,
scored by how many of them come within DEPTH_M of the observed points."""

import numpy as np
import pytest

from skt_lib.eval.methods import Proposals
from skt_lib.eval.probe_check import (DEPTH_M, REACH_M, STEP_M, UNIT_M2, ProbeSet, ordered,
                                      order_by_probes, probe_penetrations, probe_points,
                                      probe_scores)
from skt_lib.geometry.convex import Mesh
from skt_lib.geometry.skt import executed_path, skt_frames
from skt_lib.learning.predictor import Skt

T = 12


def _approach(y: float) -> np.ndarray:
    """A straight SKT along −x (toward the wall) at height 0.1 m, across at ``y``; ξ_0 first."""
    x = np.linspace(0.02, 0.14, T)
    return np.c_[x, np.full(T, y), np.full(T, 0.1)]


def _brute(candidate: np.ndarray, cloud: np.ndarray, local: np.ndarray) -> float:
    """The penetration sum by every distance, pose by pose (no tree)."""
    frames = executed_path(candidate, STEP_M, REACH_M)
    total = 0.0
    for f in frames:
        placed = local @ f[:3, :3].T + f[:3, 3]
        d = np.linalg.norm(placed[:, None] - cloud[None], axis=2).min(1)
        total += float(np.square(np.clip(DEPTH_M - d, 0.0, None)).sum())
    return total


def test_a_probe_is_its_mesh_surface_in_the_keypoint_frame():
    box = Mesh(np.array([[x, y, z] for x in (0, .04) for y in (0, .02) for z in (0, .06)], float),
               np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                         [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]]))
    kp = np.eye(4)
    kp[:3, :3] = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], float)  # 90° about x
    kp[:3, 3] = [0.01, 0.0, 0.06]  # on the top face's edge
    pts = probe_points(box, kp, 300)
    assert 250 <= len(pts) <= 300
    back = pts @ kp[:3, :3].T + kp[:3, 3]  # into the object frame again
    lo, hi = back.min(0), back.max(0)
    assert np.allclose(lo, 0, atol=2e-3) and np.allclose(hi, [.04, .02, .06], atol=2e-3)
    on_face = np.isclose(back, 0, atol=1e-9) | np.isclose(back, [.04, .02, .06], atol=1e-9)
    assert on_face.any(axis=1).all()  # every sample lies on the box's surface
    assert np.array_equal(pts, probe_points(box, kp, 300))  # seeded


def test_penetrations_are_every_pose_and_point_within_depth_of_the_cloud():
    rng = np.random.default_rng(0)
    local = rng.uniform(-0.01, 0.01, (40, 3))  # a 2 cm cube of probe points at the keypoint
    cloud = np.c_[rng.uniform(0.0, 0.16, 300), rng.uniform(-0.012, 0.012, 300),
                  np.full(300, 0.1)]  # a sheet the SKT at y = 0 runs through
    probes = ProbeSet(("cube", "far"), (local, local + [0.0, 0.0, 1.0]))
    near, away = _approach(0.0), _approach(0.2)
    pen = probe_penetrations([near, away], cloud, probes)
    assert pen.shape == (2, 2)
    assert pen[0, 0] == pytest.approx(_brute(near, cloud, local), rel=1e-9) and pen[0, 0] > 0
    assert pen[0, 1] == pen[1, 0] == pen[1, 1] == 0.0  # a metre above; 20 cm beside
    with pytest.raises(ValueError, match="at least one SKT"):
        probe_penetrations([], cloud, probes)


def test_the_score_counts_objects_that_touch_more_than_how_deep_one_cuts():
    pen = np.array([[4e-6, 4e-6, 0.0],     # two probes graze
                    [1e-4, 0.0, 0.0],      # one cuts 25 x deeper than either
                    [0.0, 0.0, 0.0]])
    got = probe_scores(pen)
    assert got == pytest.approx(np.log1p(pen / UNIT_M2).sum(1))
    # 12.5 x the two's penetration in one object scores under 1.5 x theirs
    assert got[2] == 0.0 < got[0] < got[1] < 1.5 * got[0]


def test_the_clearest_sample_comes_first_and_ties_keep_the_callers_order():
    rng = np.random.default_rng(1)
    local = rng.uniform(-0.01, 0.01, (40, 3))
    cloud = np.c_[rng.uniform(0.0, 0.16, 300), rng.uniform(-0.012, 0.012, 300),
                  np.full(300, 0.1)]
    probes = ProbeSet(("cube",), (local,))
    cands = [_approach(0.0), _approach(0.3), _approach(0.005), _approach(0.2)]
    order, scores = order_by_probes(cands, cloud, probes)
    assert scores[1] == scores[3] == 0.0 and scores[0] > 0 and scores[2] > 0
    assert list(order[:2]) == [1, 3]  # the clear ones, in the caller's order
    skts = [Skt(c, skt_frames(c), -1, c[0], np.zeros(3)) for c in cands]
    assert [s.positions[0, 1] for s in ordered(skts, cloud, probes)] == \
        [cands[i][0, 1] for i in order]


def test_proposals_run_their_samples_in_the_probes_order():
    """sim_eval's skt_flow: the samples (moved or not) ordered by the probes, so the one-SKT
    row runs the first and the best of N sees them all."""
    rng = np.random.default_rng(2)
    local = rng.uniform(-0.01, 0.01, (40, 3))
    cloud = np.c_[rng.uniform(0.0, 0.16, 300), rng.uniform(-0.012, 0.012, 300),
                  np.full(300, 0.1)]
    cands = [_approach(0.0), _approach(0.004), _approach(0.25)]

    class Fixed:
        def propose(self, cloud, rng, n):
            return [Skt(c, skt_frames(c), -1, c[0], np.zeros(3)) for c in cands[:n]]

    probes = ProbeSet(("cube",), (local,))
    got = Proposals(Fixed(), np.random.default_rng(0), 3, probes=probes).propose(cloud)
    order, _ = order_by_probes(cands, cloud, probes)
    assert order[0] == 2  # the clear one
    assert [k.positions[0, 1] for k in got] == [cands[i][0, 1] for i in order]
    plain = Proposals(Fixed(), np.random.default_rng(0), 3).propose(cloud)
    assert [k.positions[0, 1] for k in plain] == [0.0, 0.004, 0.25]  # no probes: as given


def test_a_probe_set_refuses_what_it_cannot_carry():
    with pytest.raises(ValueError, match="one point set per name"):
        ProbeSet(("a", "b"), (np.zeros((3, 3)),))
    with pytest.raises(ValueError, match="b: expected finite"):
        ProbeSet(("a", "b"), (np.zeros((3, 3)), np.full((3, 3), np.nan)))
    with pytest.raises(ValueError, match="one point set per name"):
        ProbeSet((), ())


def test_the_cell_grid_passes_every_point_within_depth_of_a_probe_and_little_more():
    """The filter is exact (no point within DEPTH_M of a probe point is dropped, for that
    probe's bit) and tight (what it passes lies within DEPTH_M plus a cell's diagonal)."""
    from scipy.spatial import cKDTree

    from skt_lib.eval.probe_check import CELL_M

    rng = np.random.default_rng(3)
    points = (rng.uniform(0.0, 0.03, (150, 3)), rng.uniform(0.02, 0.05, (150, 3)))
    grid = ProbeSet(("a", "b"), points).cells[0]
    query = rng.uniform(-0.01, 0.06, (40000, 3))
    # the identity pose: the query points are already in the keypoint frame
    pose, point, bits = grid.near(query, np.eye(3)[None], np.zeros((1, 3)))
    assert (pose == 0).all()
    for bit, own in enumerate(points):
        d, _ = cKDTree(own).query(query)
        passed = np.zeros(len(query), bool)
        passed[point[(bits >> bit) & 1 == 1]] = True
        assert passed[d < DEPTH_M].all() and (d < DEPTH_M).sum() > 200
        assert not passed[d > DEPTH_M + np.sqrt(3) * CELL_M + 1e-9].any()
        # about 2.6 x the balls' volume passes, not the 27 cells' 6.4 x
        assert passed.sum() < 3.5 * (d < DEPTH_M).sum()


def test_more_probes_than_one_grid_holds_are_each_measured():
    """70 probes: two cell grids (64 bits and 6); every probe's sum is its own, checked
    against every distance."""
    rng = np.random.default_rng(4)
    cloud = np.c_[rng.uniform(0.0, 0.16, 200), rng.uniform(-0.012, 0.012, 200),
                  np.full(200, 0.1)]
    shapes = [rng.uniform(-0.01, 0.01, (12, 3)) * rng.uniform(0.3, 1.5) for _ in range(70)]
    probes = ProbeSet(tuple(f"p{i}" for i in range(70)), tuple(shapes))
    assert [len(g.probes) for g in probes.cells] == [64, 6]
    cand = _approach(0.0)
    pen = probe_penetrations([cand, _approach(0.5)], cloud, probes)
    want = np.array([_brute(cand, cloud, local) for local in shapes])
    assert pen[0] == pytest.approx(want, rel=1e-9, abs=1e-18) and (want > 0).sum() > 30
    assert not pen[1].any()
