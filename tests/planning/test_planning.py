"""OMPL wrapper on toy scenes, the independent re-check, trajectory utilities."""

import numpy as np
import pytest

from skt_lib.geometry.convex import box, union
from skt_lib.geometry.export import write_shape
from skt_lib.geometry.se3 import matrix_pose, pose_matrix, skt_rotation
from skt_lib.parallel import run_forked
from skt_lib.planning.collision import MeshClearance, make_collision_fn
from skt_lib.planning.ompl_rrt import PlanningFailed, PlanSettings, densify, plan, seed_ompl
from skt_lib.planning.trajectory import arc_length, max_point_step, resample, skt_frames
from skt_lib.sim.world import World

CUBE_HALF = 0.01
# a 6 mm-thick plate at x = 0.2 with a 40 mm square hole: the only way from x < 0.2 to
# x > 0.2 for a 20 mm cube (the plate spans far beyond the planning bounds)
PLATE = [box([0.2, 0, zc], [0.003, 0.2, 0.1]) for zc in (0.12, -0.12)]
PLATE += [box([0.2, yc, 0], [0.003, 0.09, 0.02]) for yc in (0.11, -0.11)]
SETTINGS = PlanSettings(range_m=0.05, check_step_m=0.0015, max_checks=200_000, simplify_steps=40,
                        dense_step_m=0.001, rotation_weight_m=np.sqrt(3) * CUBE_HALF)
LOWER, UPPER = np.array([0.05, -0.08, -0.08]), np.array([0.35, 0.08, 0.08])


def _scene(tmp_path, obstacle_parts):
    obstacle = union(obstacle_parts)
    write_shape(tmp_path / "obs", "obs", obstacle, obstacle_parts, 0.0, [0, 0, 0], np.zeros((3, 3)), (1, 1, 1, 1))
    cube = box([0, 0, 0], [CUBE_HALF] * 3)
    write_shape(tmp_path / "cube", "cube", cube, [cube], 0.1, [0, 0, 0], np.eye(3) * 1e-5, (1, 0, 0, 1))
    return obstacle, cube


def _plan_in_scene(args):
    tmp_path, goal_x, max_checks = args
    obstacle, cube = _scene(tmp_path, PLATE)
    seed_ompl(7)
    with World(1 / 240, 1, with_floor=False) as world:
        obs = world.load(str(tmp_path / "obs" / "obs.urdf"), np.eye(4), True, 0.5)
        body = world.load(str(tmp_path / "cube" / "cube.urdf"), np.eye(4), False, 0.5)
        collides = make_collision_fn(world, body, [obs])
        start = pose_matrix([0.1, 0.05, 0.05], [0, 0, 0, 1])
        goal = pose_matrix([goal_x, -0.05, -0.05], [0, 0, np.sin(0.3), np.cos(0.3)])
        settings = SETTINGS if max_checks is None else SETTINGS.__class__(
            **{**SETTINGS.__dict__, "max_checks": max_checks})
        poses, _ = plan(start, goal, collides, LOWER, UPPER, settings)
        flags = [collides(*matrix_pose(t)) for t in poses]
        return poses, flags, MeshClearance(obstacle, cube, 0.002).clearance(poses)


def test_narrow_passage_is_solved_and_rechecked(tmp_path):
    poses, flags, clearance = run_forked(_plan_in_scene, (tmp_path, 0.3, None))
    assert not any(flags)
    assert clearance > 0
    assert poses[0][:3, 3] == pytest.approx([0.1, 0.05, 0.05])
    assert poses[-1][:3, 3] == pytest.approx([0.3, -0.05, -0.05])
    # through the hole: crossing x = 0.2 inside the 30 mm square
    cross = poses[np.argmin(np.abs(poses[:, 0, 3] - 0.2))][:3, 3]
    assert abs(cross[1]) < 0.02 and abs(cross[2]) < 0.02
    corners = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]) * CUBE_HALF
    assert max_point_step(poses, corners) <= 0.001 + 1e-9


def test_same_seed_same_path(tmp_path):
    a = run_forked(_plan_in_scene, (tmp_path, 0.3, None))[0]
    b = run_forked(_plan_in_scene, (tmp_path, 0.3, None))[0]
    assert np.array_equal(a, b)


def test_blocked_goal_is_a_failure_not_a_crash(tmp_path):
    with pytest.raises(PlanningFailed) as err:
        run_forked(_plan_in_scene, (tmp_path, 0.2, None))  # goal inside the plate
    assert err.value.reason == "goal_in_collision"
    with pytest.raises(PlanningFailed) as err:
        run_forked(_plan_in_scene, (tmp_path, 0.3, 300))  # reachable, but not in 300 checks
    assert err.value.reason == "no_path"


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


def test_densify_bounds_point_motion_and_keeps_inputs():
    a = pose_matrix([0, 0, 0], [0, 0, 0, 1])
    b = pose_matrix([0.05, 0.0, 0.01], [0, np.sin(0.6), 0, np.cos(0.6)])
    out = densify(np.stack([a, b]), 0.05, 0.001)
    assert np.array_equal(out[0], a) and np.allclose(out[-1], b)
    pts = np.random.default_rng(0).normal(size=(200, 3))
    pts = 0.05 * pts / np.linalg.norm(pts, axis=1, keepdims=True)
    assert max_point_step(out, pts) <= 0.001 + 1e-12


def test_resample_keeps_endpoints_and_spaces_evenly():
    t = np.linspace(0, 1, 57)
    path = np.stack([np.cos(3 * t), np.sin(3 * t), t**2], axis=1) * 0.1
    for n in (10, 20, 40):
        r = resample(path, n)
        assert r[0] == pytest.approx(path[0]) and r[-1] == pytest.approx(path[-1])
        s = arc_length(r)
        assert np.all(np.diff(s) > 0)  # monotone
        # equal spacing along the original curve (chords slightly shorter than arcs)
        assert np.diff(s) == pytest.approx(np.full(n - 1, arc_length(path)[-1] / (n - 1)), rel=0.02)
    with pytest.raises(ValueError, match="n"):
        resample(path, 1)
    with pytest.raises(ValueError, match="zero-length"):
        resample(np.zeros((5, 3)), 4)


def test_skt_frames_follow_the_rule():
    pos = np.array([[0.0, 0, 0], [0.05, 0, 0.01], [0.1, 0.02, 0.05], [0.1, 0.02, 0.1]])
    frames = skt_frames(pos)
    for i, f in enumerate(frames):
        r = f[:3, :3]
        assert r.T @ r == pytest.approx(np.eye(3), abs=1e-12) and np.linalg.det(r) == pytest.approx(1)
        assert f[:3, 3] == pytest.approx(pos[i])
    assert frames[0][:3, :3] == pytest.approx(skt_rotation(pos[0] - pos[1]))
    # the last segment is vertical: its frame falls back to the nearest defined one
    assert frames[3][:3, :3] == pytest.approx(frames[2][:3, :3])
