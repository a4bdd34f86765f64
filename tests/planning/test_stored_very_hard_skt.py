"""A stored Very Hard SKT (support_00063, a double hook whose tip rises 5.6 cm: the ring goes
over the tip and down along it, then in to the hang), replayed as sim_eval executes it.
The fixture comes from the pipeline (`tools/make_skt_fixture.py`)."""

from pathlib import Path

import numpy as np
import pytest

from skt_lib.geometry.convex import Mesh
from skt_lib.geometry.se3 import invert
from skt_lib.geometry.skt import executed_path, interpolate, resample, rule_frames
from skt_lib.planning.collision import MeshClearance
from skt_lib.planning.skts import REACH_TOL_M

FIXTURE = Path(__file__).parents[1] / "fixtures" / "very_hard_skt.npz"
T = 40


@pytest.fixture(scope="module")
def stored():
    with np.load(FIXTURE) as z:
        d = {k: z[k] for k in z.files}
    d["clearance"] = MeshClearance(Mesh(d["support_vertices"], d["support_faces"]),
                                   Mesh(d["ring_vertices"], d["ring_faces"]), 0.002)
    d["radius"] = float(np.linalg.norm(d["ring_vertices"] - d["ring_keypoint"][:3, 3], axis=1).max())
    return d


def test_it_ends_at_the_hang_and_threads_down_the_tip(stored):
    kp = stored["keypoints"]
    assert np.linalg.norm(kp[0] - stored["hang_keypoint"]) <= REACH_TOL_M
    seg = np.diff(kp[::-1], axis=0)
    seg /= np.linalg.norm(seg, axis=1, keepdims=True)
    assert np.degrees(np.arcsin(-seg[:, 2])).max() > 75.0  # down the tip, steeper than 75°


def test_replayed_as_executed_it_is_clear_for_the_reference(stored):
    frames = executed_path(resample(stored["keypoints"], T), 0.001, stored["radius"])
    assert np.linalg.norm(frames[-1][:3, 3] - stored["hang_keypoint"]) <= REACH_TOL_M
    assert stored["clearance"].clearance(frames @ invert(stored["ring_keypoint"])) > 0


def test_with_the_rule_frames_the_same_positions_collide(stored):
    """The old contract (the paper's rule; vertical motion takes the nearest defined frame)
    drives the ring into the hook along the same positions."""
    rule = rule_frames(resample(stored["keypoints"], T))
    defined = np.flatnonzero(np.isfinite(rule[:, 0, 1]))
    nearest = defined[np.abs(defined[None, :] - np.arange(T)[:, None]).argmin(1)]
    rule[:, :3, :3] = rule[nearest, :3, :3]
    frames = interpolate(rule[::-1], 0.001, stored["radius"])
    assert stored["clearance"].clearance(frames @ invert(stored["ring_keypoint"])) < 0
