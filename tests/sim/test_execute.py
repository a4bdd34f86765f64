"""The trial executor: interpolation bound, grasp frame, determinism, and the predicate's
still-in-gripper case with a real Panda."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from skt_lib.geometry.se3 import pose_matrix, transform_points
from skt_lib.planning.trajectory import interpolate
from skt_lib.sim.execute import grasp_in_keypoint
from skt_lib.sim.hanging import check_hang, perturb
from skt_lib.sim.robot import Panda
from tests.sim.test_hanging import PERT, _ring_world, _settle_from


def _random_frames(rng, n):
    out = np.tile(np.eye(4), (n, 1, 1))
    out[:, :3, :3] = Rotation.random(n, random_state=3).as_matrix()
    out[:, :3, 3] = np.cumsum(rng.normal(scale=0.02, size=(n, 3)), axis=0)
    return out


def test_interpolation_moves_no_point_more_than_the_step():
    rng = np.random.default_rng(0)
    frames = _random_frames(rng, 6)
    radius, step = 0.08, 0.002
    path = interpolate(frames, step, radius)
    # every given frame is on the path, in order, first and last exactly
    assert np.allclose(path[0], frames[0]) and np.allclose(path[-1], frames[-1])
    idx = [int(np.argmin(np.abs(path - f).sum((1, 2)))) for f in frames]
    assert idx == sorted(idx) and all(np.allclose(path[i], f) for i, f in zip(idx, frames))
    # points on a sphere of the given radius never jump more than the step
    pts = rng.normal(size=(200, 3))
    pts = radius * pts / np.linalg.norm(pts, axis=1, keepdims=True)
    moved = np.stack([transform_points(t, pts) for t in path])
    assert np.linalg.norm(np.diff(moved, axis=0), axis=2).max() <= step + 1e-9
    # and the bound is not met by wasting commands: a coarser step needs fewer poses
    assert len(interpolate(frames, 2 * step, radius)) < 0.6 * len(path)


@pytest.mark.parametrize("pitch", [0.0, 30.0])
def test_grasp_is_behind_the_lowest_part_and_approaches_along_keypoint_x(pitch):
    rng = np.random.default_rng(1)
    verts = rng.uniform([-0.02, -0.03, -0.12], [0.02, 0.03, 0.01], size=(500, 3))
    keypoint = pose_matrix([0.0, 0.0, 0.01], Rotation.from_euler("z", 30, degrees=True).as_quat())
    g = grasp_in_keypoint(verts, keypoint, pitch, band_m=0.02, standoff_m=0.01)
    r = g[:3, :3]
    assert np.allclose(r.T @ r, np.eye(3)) and np.linalg.det(r) == pytest.approx(1.0)
    p = np.radians(pitch)
    assert np.allclose(r[:, 2], [np.cos(p), 0, -np.sin(p)])  # approach: keypoint +x, pitched down
    v = transform_points(np.linalg.inv(keypoint), verts)
    low = v[v[:, 2] <= v[:, 2].min() + 0.02]
    assert g[0, 3] == pytest.approx(low[:, 0].min() - 0.01)
    assert v[:, 2].min() <= g[2, 3] <= v[:, 2].min() + 0.02


def test_predicate_rejects_an_object_still_in_the_gripper(tmp_path):
    world, rod, ring = _ring_world(tmp_path)
    with world:
        hung = pose_matrix([0.12, 0, 0.009 - 0.0215], [0, 0, 0, 1])
        assert _settle_from(world, rod, ring, hung).ok  # hangs on its own …
        # … then the hand closes on its weight (below the ring) and never lets go
        weight = world.pose_support(ring) @ pose_matrix([0, 0, -(0.026 + 0.015)], [0, 0, 0, 1])
        grasp = np.eye(4)
        grasp[:3, :3] = np.array([[0.0, 0.0, -1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]])  # approach −x
        grasp[:3, 3] = weight[:3, 3]
        robot = Panda(world, pose_matrix([0.05, 0.0, 0.3], [0, 0, 0, 1]))
        assert robot.joint_path([world.to_world(grasp)], 0.002, 0.02, 0.2, 12) is not None
        robot.command_fingers(0.0)
        world.step(120)
        perturb(world, PERT)
        check = check_hang(world, ring, rod, robot.body)
        assert not check.ok and check.reason == "touches_robot"
        assert world.contacts(ring, rod)  # it is on the rod: only the gripper makes it fail
