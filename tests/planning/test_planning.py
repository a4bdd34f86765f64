"""The independent re-check on a toy scene, trajectory utilities."""

import numpy as np
import pytest

from skt_lib.geometry.convex import box, union
from skt_lib.geometry.export import write_shape
from skt_lib.geometry.se3 import pose_matrix, skt_rotation
from skt_lib.planning.collision import MeshClearance
from skt_lib.geometry.skt import arc_length, resample, skt_frames

CUBE_HALF = 0.01
# a 6 mm-thick plate at x = 0.2 with a 40 mm square hole: the only way from x < 0.2 to
# x > 0.2 for a 20 mm cube (the plate spans far beyond the planning bounds)
PLATE = [box([0.2, 0, zc], [0.003, 0.2, 0.1]) for zc in (0.12, -0.12)]
PLATE += [box([0.2, yc, 0], [0.003, 0.09, 0.02]) for yc in (0.11, -0.11)]


def _scene(tmp_path, obstacle_parts):
    obstacle = union(obstacle_parts)
    write_shape(tmp_path / "obs", "obs", obstacle, obstacle_parts, 0.0, [0, 0, 0], np.zeros((3, 3)), (1, 1, 1, 1))
    cube = box([0, 0, 0], [CUBE_HALF] * 3)
    write_shape(tmp_path / "cube", "cube", cube, [cube], 0.1, [0, 0, 0], np.eye(3) * 1e-5, (1, 0, 0, 1))
    return obstacle, cube


def test_recheck_sees_a_collision_the_planner_would_see(tmp_path):
    obstacle, cube = _scene(tmp_path, PLATE)
    check = MeshClearance(obstacle, cube, 0.002)
    free = pose_matrix([0.1, 0.06, 0], [0, 0, 0, 1])  # far: reported at the 6 mm cap
    assert check.clearance(free) == pytest.approx(0.006)
    near = pose_matrix([0.184, 0.06, 0], [0, 0, 0, 1])  # cube face 3 mm from the plate
    assert check.clearance(near) == pytest.approx(0.003, abs=1e-4)
    stuck = pose_matrix([0.2, 0.06, 0.0], [0, 0, 0, 1])  # cube straddling the plate
    assert check.clearance(stuck) < 0
    assert check.clearance(np.stack([free, stuck])) < 0


def test_resample_keeps_endpoints_and_spaces_evenly():
    """By arc length alone (``turn_radius_m=0``) waypoints are evenly spaced along the curve;
    with turning, steps weigh travel plus turn (turning_length) evenly."""
    t = np.linspace(0, 1, 57)
    path = np.stack([np.cos(3 * t), np.sin(3 * t), t**2], axis=1) * 0.1
    for n in (10, 20, 40):
        r = resample(path, n, turn_radius_m=0.0)
        assert r[0] == pytest.approx(path[0]) and r[-1] == pytest.approx(path[-1])
        s = arc_length(r)
        assert np.all(np.diff(s) > 0)  # monotone
        # equal spacing along the original curve (chords slightly shorter than arcs)
        assert np.diff(s) == pytest.approx(np.full(n - 1, arc_length(path)[-1] / (n - 1)), rel=0.02)
        w = resample(path, n)
        assert w[0] == pytest.approx(path[0]) and w[-1] == pytest.approx(path[-1])
        assert np.all(np.diff(arc_length(w)) > 0)
    with pytest.raises(ValueError, match="n"):
        resample(path, 1)
    with pytest.raises(ValueError, match="zero-length"):
        resample(np.zeros((5, 3)), 4)


def test_skt_frames_are_orthonormal_and_anchored_at_the_rule():
    pos = np.array([[0.0, 0, 0], [0.05, 0, 0.01], [0.1, 0.02, 0.05], [0.1, 0.02, 0.1]])
    frames = skt_frames(pos)
    for i, f in enumerate(frames):
        r = f[:3, :3]
        assert r.T @ r == pytest.approx(np.eye(3), abs=1e-12) and np.linalg.det(r) == pytest.approx(1)
        assert f[:3, 3] == pytest.approx(pos[i])
    assert frames[0][:3, :3] == pytest.approx(skt_rotation(pos[0] - pos[1]))
    # the last waypoint (the start) takes the motion leaving it, without a further turn
    assert frames[3][:3, :3] == pytest.approx(frames[2][:3, :3])
