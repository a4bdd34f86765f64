"""Set-up IK and the grasp chooser on the Panda, kinematic only (no stepping)."""

import numpy as np
import pytest

from skt_lib.geometry.se3 import pose_matrix
from skt_lib.sim.grasp import Grasp, GraspChoice, GraspFailure, choose_grasp
from skt_lib.sim.robot import IKFailure, Panda
from skt_lib.sim.world import World
from tests.sim import scenes

BASE = pose_matrix([0.15, 0.0, 0.3], [0, 0, 0, 1])


@pytest.fixture
def panda():
    with World(1 / 240, 50, with_floor=False) as world:
        yield world, Panda(world, BASE)


def _fk_path(robot, qa, qb, n):
    """Grasp-target world poses along the joint-space line qa → qb: a Cartesian path known
    to be feasible (curved, with changing orientation)."""
    out = []
    for u in np.linspace(0.0, 1.0, n):
        robot.reset((1 - u) * qa + u * qb, 0.04)
        out.append(robot.grasp_world())
    return out


def test_ik_tracks_a_known_feasible_path_within_tolerance_and_limits(panda):
    world, robot = panda
    qa = np.array([0.3, 0.2, -0.2, -1.8, 0.1, 2.0, 0.5])
    qb = np.array([-0.3, 0.5, 0.2, -1.4, -0.2, 1.7, 1.0])
    targets = _fk_path(robot, qa, qb, 120)
    robot.reset((0.0,) * 7, 0.04)  # start far from the path
    joints = robot.joint_path(targets, 0.002, 0.02, 0.2, 4)
    assert not isinstance(joints, IKFailure), joints
    assert joints.shape == (120, 7)
    assert (joints >= robot.lower - 1e-9).all() and (joints <= robot.upper + 1e-9).all()
    assert np.abs(np.diff(joints, axis=0)).max() <= 0.2  # continuity
    for q, t in zip(joints, targets):  # every pose checked by forward kinematics
        robot.reset(q, 0.04)
        d, a = robot.pose_error(t)
        assert d <= 0.002 and a <= 0.02
    # and much tighter than the tolerance: each pose is solved to 0.1 mm
    errs = []
    for q, t in zip(joints, targets):
        robot.reset(q, 0.04)
        errs.append(robot.pose_error(t)[0])
    assert np.median(errs) < 2e-4


def test_ik_failure_says_which_check_failed(panda):
    world, robot = panda
    far = [pose_matrix([2.0, 0.0, 1.0], [0, 0, 0, 1])] * 3
    out = robot.joint_path(far, 0.002, 0.02, 0.2, 3)
    assert isinstance(out, IKFailure) and out.check == "unreachable_hang" and out.index == 2
    # a jump of 90° about the approach axis between consecutive poses: reachable, but not
    # within 0.2 rad of joint motion (tracked backward from the hang, it shows at pose 1)
    t0 = _fk_path(robot, np.array([0.0, 0.2, 0.0, -1.8, 0.0, 2.0, 0.0]),
                  np.array([0.0, 0.2, 0.0, -1.8, 0.0, 2.0, 0.0]), 1)[0]
    turned = t0 @ pose_matrix([0, 0, 0], [0, 0, np.sin(np.pi / 4), np.cos(np.pi / 4)])
    out = robot.joint_path([t0, t0, turned], 0.002, 0.02, 0.2, 3)
    assert isinstance(out, IKFailure) and out.check == "joint_jump" and out.index == 1, out
    assert out.jump_rad > 0.2 and "joint_jump at pose 1/3" in out.describe()


@pytest.fixture(scope="module")
def ring_scene(tmp_path_factory):
    d = tmp_path_factory.mktemp("chooser")
    ring, vertices = scenes.build_ring(d)
    return scenes.write_support(d), ring, vertices


def _choose(ring_scene, grasps, positions):
    from skt_lib.geometry.se3 import invert
    from skt_lib.geometry.skt import executed_path

    support_urdf, ring_urdf, _ = ring_scene
    path = executed_path(positions, 0.002, scenes.RING_RADIUS_M)
    with World(1 / 240, 50) as world:
        wall = world.add_wall()
        support = world.load(support_urdf, np.eye(4), fixed=True, friction=0.6)
        obj = world.load(ring_urdf, path[0] @ invert(scenes.RING_KEYPOINT), fixed=False, friction=0.6)
        robot = Panda(world, BASE)
        out = choose_grasp(world, robot, path, grasps, [support, wall], obj, 0.002, 0.02, 0.2, 4, 0.002)
        if isinstance(out, GraspChoice):  # the arm is left at the chosen path's start
            assert np.allclose(robot.q(), out.joints[0], atol=1e-9)
        return out


def test_chooser_takes_the_first_reachable_candidate_in_order(ring_scene):
    *_, vertices = ring_scene
    from skt_lib.sim.grasp import grasp_candidates

    good = grasp_candidates(vertices, scenes.RING_KEYPOINT, (45.0,), (0.0,))[0]
    away = np.asarray(good.kpt_ee).reshape(4, 4).copy()
    away[:3, 3] += [0.0, 0.0, -1.5]  # a hand 1.5 m below the object: out of reach
    unreachable = Grasp("below", tuple(away.ravel()))
    out = _choose(ring_scene, (unreachable, good), scenes.straight_skt())
    assert isinstance(out, GraspChoice) and out.index == 1 and out.grasp is good
    assert out.joints.shape[1] == 7 and len(out.joints) > 20


def test_chooser_reports_why_no_candidate_works(ring_scene):
    *_, vertices = ring_scene
    from skt_lib.sim.grasp import grasp_candidates

    grasps = grasp_candidates(vertices, scenes.RING_KEYPOINT, (45.0, 30.0), (0.0,))
    out = _choose(ring_scene, grasps, scenes.straight_skt(offset=(0.0, 1.5, 0.0)))
    assert isinstance(out, GraspFailure) and len(out.failures) == 2
    assert {f.check for f in out.failures} == {"unreachable_hang"}
    assert out.describe().startswith("no reachable grasp (2 tried: 2 unreachable_hang)")
    # a hand inside the wall: reachable, but not clear of it
    inside = np.asarray(grasps[0].kpt_ee).reshape(4, 4).copy()
    inside[:3, 3] = [0.0, 0.0, 0.0]
    start_x = scenes.straight_skt()[-1, 0]
    inside[0, 3] = start_x + 0.01  # keypoint +x points at the wall: 1 cm into it
    out = _choose(ring_scene, (Grasp("in_wall", tuple(inside.ravel())),), scenes.straight_skt())
    assert isinstance(out, GraspFailure) and out.failures[0].check == "clearance", out
