"""The trial executor's parts: interpolation bound, grasp frames, and the predicate's
still-in-gripper case with a real Panda."""

import re

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from skt_lib.geometry.se3 import pose_matrix, transform_points
from skt_lib.geometry.skt import interpolate
from skt_lib.sim.grasp import HAND_RADIUS_M, grasp_along, grasp_candidates, grasp_in_keypoint, \
    sphere_directions
from skt_lib.sim.hanging import check_hang, perturb
from skt_lib.sim.robot import IKFailure, Panda
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


@pytest.mark.parametrize("yaw,pitch,roll", [(0.0, 0.0, 0.0), (0.0, 30.0, 0.0), (0.0, 45.0, 180.0),
                                            (0.0, 60.0, -30.0), (90.0, 30.0, 0.0),
                                            (-90.0, 45.0, 90.0), (180.0, 60.0, 0.0)])
def test_grasp_approaches_the_lowest_part_with_the_hand_clear_of_the_object(yaw, pitch, roll):
    rng = np.random.default_rng(1)
    # an L-shaped object: a long arm sticks out sideways above the lowest part, so a hand
    # placed only by the lowest band would sit inside it for some approaches
    verts = np.concatenate([rng.uniform([-0.02, -0.03, -0.12], [0.02, 0.03, 0.01], size=(500, 3)),
                            rng.uniform([-0.12, -0.12, -0.09], [0.12, 0.12, -0.07], size=(500, 3))])
    keypoint = pose_matrix([0.0, 0.0, 0.01], Rotation.from_euler("z", 30, degrees=True).as_quat())
    g = grasp_in_keypoint(verts, keypoint, pitch, roll, band_m=0.02, standoff_m=0.01, yaw_deg=yaw)
    r = g[:3, :3]
    assert np.allclose(r.T @ r, np.eye(3)) and np.linalg.det(r) == pytest.approx(1.0)
    p, q, y = np.radians(pitch), np.radians(roll), np.radians(yaw)
    # approach: keypoint +x turned by the yaw about keypoint z, pitched down
    assert np.allclose(r[:, 2], [np.cos(p) * np.cos(y), np.cos(p) * np.sin(y), -np.sin(p)])
    # roll turns the hand's y axis about the approach: roll 0 → keypoint −y turned by the yaw
    assert np.dot(r[:, 1], [np.sin(y), -np.cos(y), 0]) == pytest.approx(np.cos(q))
    v = transform_points(np.linalg.inv(keypoint), verts)
    centre = v[v[:, 2] <= v[:, 2].min() + 0.02].mean(axis=0)
    d = r[:, 2]
    rel = g[:3, 3] - centre
    assert np.linalg.norm(rel - (rel @ d) * d) < 1e-12  # on the approach line through the band
    # every object point within the hand's radius of that line is ≥ the standoff ahead of
    # the fingertips, and one is exactly at it
    along = (v - g[:3, 3]) @ d
    lateral = np.linalg.norm((v - g[:3, 3]) - along[:, None] * d, axis=1)
    near = along[lateral <= HAND_RADIUS_M]
    assert near.min() == pytest.approx(0.01)


def test_grasp_candidates_come_yaw_major_then_pitch_in_the_given_order():
    verts = np.random.default_rng(2).uniform(-0.05, 0.05, size=(200, 3))
    c = grasp_candidates(verts, np.eye(4), (45.0, 30.0), (0.0, 180.0))
    assert [g.label for g in c] == ["pitch45_roll0", "pitch45_roll180", "pitch30_roll0",
                                    "pitch30_roll180"]
    assert np.allclose(c[2].matrix(), grasp_in_keypoint(verts, np.eye(4), 30.0, 0.0))
    c = grasp_candidates(verts, np.eye(4), (45.0,), (0.0,), yaws_deg=(0.0, 90.0, -90.0))
    assert [g.label for g in c] == ["pitch45_roll0", "yaw90_pitch45_roll0", "yaw-90_pitch45_roll0"]
    assert np.allclose(c[1].matrix(), grasp_in_keypoint(verts, np.eye(4), 45.0, 0.0, yaw_deg=90.0))


@pytest.mark.parametrize("n", [1, 8, 32])
def test_sphere_directions_are_unit_and_spread_over_the_whole_sphere(n):
    d = sphere_directions(n)
    assert d.shape == (n, 3) and np.allclose(np.linalg.norm(d, axis=1), 1.0)
    if n >= 8:  # from below and from above, and no two alike
        assert d[:, 2].max() > 0.8 and d[:, 2].min() < -0.8
        gap = np.linalg.norm(d[:, None] - d[None], axis=2) + 9 * np.eye(n)
        assert gap.min() > 0.5 * np.sqrt(4 * np.pi / n)
    assert np.array_equal(d, sphere_directions(n))


@pytest.mark.parametrize("approach", [(0, 0, 1), (0, 0, -1), (1, 0, 0), (0.3, -0.8, 0.5),
                                      (-0.2, 0.1, -0.97)])
@pytest.mark.parametrize("roll", [0.0, 90.0, -90.0])
def test_grasp_along_approaches_along_the_given_direction_clear_of_the_object(approach, roll):
    rng = np.random.default_rng(3)
    verts = rng.uniform([-0.04, -0.03, -0.1], [0.04, 0.03, 0.02], size=(800, 3))
    keypoint = pose_matrix([0.0, 0.01, 0.0], Rotation.from_euler("x", 20, degrees=True).as_quat())
    g = grasp_along(verts, keypoint, approach, roll)
    r = g[:3, :3]
    assert np.allclose(r.T @ r, np.eye(3)) and np.linalg.det(r) == pytest.approx(1.0)
    d = np.asarray(approach, float) / np.linalg.norm(approach)
    assert np.allclose(r[:, 2], d)
    # roll 0: the hand's x axis along keypoint +z × approach (+x × approach near ±z)
    ref = np.array([0.0, 0.0, 1.0]) if abs(d[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    x_roll0 = np.cross(ref, d) / np.linalg.norm(np.cross(ref, d))
    assert np.dot(r[:, 0], x_roll0) == pytest.approx(np.cos(np.radians(roll)), abs=1e-12)
    # the roll turns the hand about the approach: 90° apart → x axes at right angles
    x0 = grasp_along(verts, keypoint, approach, roll - 90.0)[:3, 0]
    assert np.dot(r[:, 0], x0) == pytest.approx(0.0, abs=1e-12)
    v = transform_points(np.linalg.inv(keypoint), verts)
    along = (v - g[:3, 3]) @ d
    lateral = np.linalg.norm((v - g[:3, 3]) - along[:, None] * d, axis=1)
    assert along[lateral <= HAND_RADIUS_M].min() == pytest.approx(0.01)


def test_sphere_grasps_come_after_the_grid_which_they_leave_as_it_was():
    verts = np.random.default_rng(2).uniform(-0.05, 0.05, size=(200, 3))
    grid = grasp_candidates(verts, np.eye(4), (45.0, 30.0), (0.0, 180.0), yaws_deg=(0.0, 90.0))
    both = grasp_candidates(verts, np.eye(4), (45.0, 30.0), (0.0, 180.0), yaws_deg=(0.0, 90.0),
                            sphere=3)
    assert both[:len(grid)] == grid
    assert [g.label for g in both[len(grid):]] == ["sphere0_roll0", "sphere0_roll180",
                                                   "sphere1_roll0", "sphere1_roll180",
                                                   "sphere2_roll0", "sphere2_roll180"]
    assert np.allclose(both[-1].matrix(), grasp_along(verts, np.eye(4), sphere_directions(3)[2],
                                                      180.0))


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
        robot = Panda(world, pose_matrix([0.15, 0.0, 0.3], [0, 0, 0, 1]))
        assert not isinstance(robot.joint_path([world.to_world(grasp)], 0.002, 0.02, 0.2, 12), IKFailure)
        robot.command_fingers(0.0)
        world.step(120)
        perturb(world, PERT)
        check = check_hang(world, ring, rod, PERT, robot.body)
        assert not check.ok and check.reason == "touches_robot"
        assert world.contacts(ring, rod)  # it is on the rod: only the gripper makes it fail


@pytest.mark.parametrize("key,value,message", [
    ("grasp_pitch_deg", [45.0, 95.0], "sim_eval: grasp_pitch_deg: each pitch must lie in [0, 90)"),
    ("grasp_rolls_deg", [0.0, 0.0], "sim_eval: grasp_rolls_deg: duplicate entries"),
    ("grasp_pitch_deg", [], "sim_eval.grasp_pitch_deg"),
    ("methods", ["oracle", "oracle_hovering"], "sim_eval.methods"),
])
def test_grasp_and_method_params_are_validated(tiny_dict, key, value, message):
    from skt_lib.config.params_file import parse_params
    from skt_lib.errors import ParamsError

    tiny_dict["sim_eval"][key] = value
    with pytest.raises(ParamsError, match=re.escape(message)):
        parse_params(tiny_dict)
