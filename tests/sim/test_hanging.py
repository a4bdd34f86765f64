"""The success predicate on hand-made scenes: it accepts a hung object and rejects a dropped,
a perched, a never-reached, a still-swinging one and one resting on the wall plate only."""

import numpy as np
import pybullet as pb
import pytest

from skt_lib.geometry.se3 import pose_matrix
from skt_lib.sim.contact_sim import add_rod
from skt_lib.sim.hanging import Perturbation, check_hang, perturb, supporting_cluster
from skt_lib.sim.world import World

PERT = Perturbation(4.0, 240, 960, 0.02, 0.15, 120)


def _ring_world(urdf_dir):
    from skt_lib.config import MeshGenParams
    from skt_lib.geometry.build import ObjectTask, build_object
    from tests.conftest import TINY

    row = build_object(ObjectTask(0, "reference", 0, MeshGenParams(**TINY["mesh_gen"]), str(urdf_dir)))
    world = World(1 / 240, 50)
    world.add_wall()
    rod = add_rod(world, 0.005, 0.6)
    ring = world.load(str(urdf_dir / row["urdf_path"]), pose_matrix([0.5, 0, 2], [0, 0, 0, 1]),
                      fixed=False, friction=0.6, linear_damping=1.0,
                      angular_damping=5.0)
    return world, rod, ring


def _settle_from(world, rod, body, t):
    world.set_pose_support(body, t)
    world.step(480)
    perturb(world, PERT)
    return check_hang(world, body, rod, PERT)


@pytest.fixture
def scene(tmp_path):
    world, rod, ring = _ring_world(tmp_path)
    yield world, rod, ring
    world.close()


def test_accepts_object_hung_on_rod(scene):
    world, rod, ring = scene
    # ring (aperture radius ~21 mm) threaded on the rod, its inner top 4 mm above the rod
    check = _settle_from(world, rod, ring, pose_matrix([0.12, 0, 0.009 - 0.0215], [0, 0, 0, 1]))
    assert check.ok, check.reason
    assert check.contact_support[2] == pytest.approx(0.005, abs=0.003)  # top of the rod
    assert world.com_support(ring)[2] < 0  # hangs below the rod


def test_rejects_object_dropped_next_to_the_rod(scene):
    world, rod, ring = scene
    check = _settle_from(world, rod, ring, pose_matrix([0.12, 0.08, 0.0], [0, 0, 0, 1]))
    assert not check.ok and check.reason == "touches_floor"


def test_rejects_object_lying_on_top(scene):
    world, rod, ring = scene
    # ring lying flat (aperture axis vertical) on top of the rod, centred on it
    flat = pose_matrix([0.12, 0, 0.005 + 0.0042], [0, np.sin(np.pi / 4), 0, np.cos(np.pi / 4)])
    world.set_pose_support(ring, flat)
    world.step(60)
    check = check_hang(world, ring, rod, PERT)
    assert not check.ok and check.reason == "perched"


def test_rejects_object_that_never_reached_the_support(tmp_path):
    world, rod, ring = _ring_world(tmp_path)
    with world:
        pb.removeBody(world.floor, physicsClientId=world.cid)
        world.floor = None
        world.set_pose_support(ring, pose_matrix([0.4, 0.3, 0.0], [0, 0, 0, 1]))
        world.step(120)
        assert check_hang(world, ring, rod, PERT).reason == "no_contact"


def test_gravity_is_normal_after_perturbation(scene):
    world, _, _ = scene
    perturb(world, Perturbation(4.0, 1, 1, 0.01, 0.1, 1))
    # a free sphere now falls straight down in the support frame
    s = pb.createMultiBody(1.0, pb.createCollisionShape(pb.GEOM_SPHERE, radius=0.01,
                                                        physicsClientId=world.cid),
                           physicsClientId=world.cid)
    world._inertial[s] = np.eye(4)  # a primitive: its link frame is its COM frame
    world.set_pose_support(s, pose_matrix([0.3, 0.3, 0.0], [0, 0, 0, 1]))
    world.step(24)
    drift = world.pose_support(s)[:3, 3] - np.array([0.3, 0.3, 0.0])
    assert abs(drift[0]) < 1e-9 and abs(drift[1]) < 1e-9 and drift[2] < -0.01


def test_supporting_cluster_takes_the_loaded_cluster():
    pts = np.array([[0, 0, 0], [0.001, 0, 0], [0.05, 0, 0], [0.051, 0, 0.001]])
    forces = np.array([1.0, 1.0, 5.0, 3.0])
    c = supporting_cluster(pts, forces)
    assert c == pytest.approx((pts[2] * 5 + pts[3] * 3) / 8)
    with pytest.raises(ValueError):
        supporting_cluster(np.zeros((0, 3)), np.zeros(0))


def test_rejects_object_still_swinging_unless_it_settles(scene):
    world, rod, ring = scene
    assert _settle_from(world, rod, ring, pose_matrix([0.12, 0, 0.009 - 0.0215], [0, 0, 0, 1])).ok
    # the hung ring pushed into a swing about the rod: judged at once, it is still moving …
    pb.resetBaseVelocity(ring, [0, 0, 0], [5.0, 0, 0], physicsClientId=world.cid)
    quick = Perturbation(4.0, 1, 1, PERT.rest_speed_m_s, PERT.rest_angular_speed_rad_s, 30)
    check = check_hang(world, ring, rod, quick)
    assert not check.ok and check.reason == "not_at_rest"
    assert world.contacts(ring, rod)  # on the rod: only the motion makes it fail
    # … and once it has settled it is accepted
    world.step(PERT.settle_steps)
    assert check_hang(world, ring, rod, PERT).ok


def test_rejects_object_resting_on_the_wall_plate_only(tmp_path):
    from tests.sim import scenes

    world, _, ring = _ring_world(tmp_path)
    with world:
        support = world.load(scenes.write_support(tmp_path), np.eye(4), fixed=True, friction=0.6)
        # the ring hung on the tab that sticks 1 cm out of the plate (all of it at x ≤ 1 cm)
        top = scenes.TAB_Z_M + 0.003
        world.set_pose_support(ring, pose_matrix([0.005, scenes.TAB_Y_M, top - scenes.RING_INNER_M - 0.001],
                                                 [0, 0, 0, 1]))
        world.step(480)
        check = check_hang(world, ring, support, PERT)
        assert world.contacts(ring, support)  # it does rest on the support …
        assert world.com_support(ring)[2] < top  # … below it, not perched …
        assert not check.ok and check.reason == "on_wall_plate"  # … but only on the plate
