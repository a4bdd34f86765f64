"""The success predicate on hand-made scenes: it accepts a hung object and rejects a dropped,
a perched, a never-reached, a still-swinging one, one touching the robot and one resting on
the wall plate only; its parts (the perturbation phases, the supporting contact cluster, the
motion observed over the rest window) against values worked out by hand."""

import numpy as np
import pybullet as pb
import pytest

from skt_lib.geometry.se3 import pose_matrix
from skt_lib.sim.contact_sim import add_rod
from skt_lib.sim.hanging import (G, HangCheck, Perturbation, check_hang, observe_motion, perturb,
                                 perturb_phases, supporting_cluster)
from skt_lib.sim.world import SUPPORT_POSE_WORLD, World

PERT = Perturbation(4.0, 240, 960, 0.02, 0.15, 120)


def _ring_world(urdf_dir):
    from skt_lib.config.mesh_gen import MeshGenParams
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
    assert check.ok is True and check.reason == "ok", check.reason
    assert check.contact_support[2] == pytest.approx(0.005, abs=0.003)  # top of the rod
    assert world.com_support(ring)[2] < 0  # hangs below the rod
    # the same point in the ring's frame: the top of its aperture (inner radius ≈ 21 mm)
    assert check.contact_object.shape == (3,)
    assert check.contact_object == pytest.approx([0.0, 0.0, 0.021], abs=0.0015)
    t = world.pose_support(ring)
    assert (t @ np.append(check.contact_object, 1.0))[:3] == pytest.approx(check.contact_support, abs=1e-12)


def test_rejects_object_dropped_next_to_the_rod(scene):
    world, rod, ring = scene
    check = _settle_from(world, rod, ring, pose_matrix([0.12, 0.08, 0.0], [0, 0, 0, 1]))
    assert check == HangCheck(False, "touches_floor")


def test_rejects_object_lying_on_top(scene):
    world, rod, ring = scene
    # ring lying flat (aperture axis vertical) on top of the rod, centred on it
    flat = pose_matrix([0.12, 0, 0.005 + 0.0042], [0, np.sin(np.pi / 4), 0, np.cos(np.pi / 4)])
    world.set_pose_support(ring, flat)
    world.step(60)
    check = check_hang(world, ring, rod, PERT)
    assert check.ok is False and check.reason == "perched"
    assert check.contact_support[2] == pytest.approx(0.005, abs=0.001)  # on top of the rod …
    assert world.com_support(ring)[2] > check.contact_support[2]  # … with the ring above it


def test_rejects_object_that_never_reached_the_support(tmp_path):
    world, rod, ring = _ring_world(tmp_path)
    with world:
        pb.removeBody(world.floor, physicsClientId=world.cid)
        world.floor = None
        world.set_pose_support(ring, pose_matrix([0.4, 0.3, 0.0], [0, 0, 0, 1]))
        world.step(120)
        assert check_hang(world, ring, rod, PERT) == HangCheck(False, "no_contact")


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
    assert _settle_from(world, rod, ring, pose_matrix([0.12, 0, 0.009 - 0.0215], [0, 0, 0, 1])).ok is True
    # the hung ring pushed into a swing about the rod: judged at once, it is still moving …
    pb.resetBaseVelocity(ring, [0, 0, 0], [5.0, 0, 0], physicsClientId=world.cid)
    quick = Perturbation(4.0, 1, 1, PERT.rest_speed_m_s, PERT.rest_angular_speed_rad_s, 30)
    check = check_hang(world, ring, rod, quick)
    assert check == HangCheck(False, "not_at_rest")
    assert world.contacts(ring, rod)  # on the rod: only the motion makes it fail
    # … and once it has settled it is accepted
    world.step(PERT.settle_steps)
    assert check_hang(world, ring, rod, PERT).ok is True


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
        assert check == HangCheck(False, "on_wall_plate")  # … but only on the plate


# -- perturb_phases / perturb ------------------------------------------------------------

def test_perturb_phases_lists_the_tilts_then_the_settling():
    p = Perturbation(2.5, 3, 7, 0.01, 0.1, 11)
    assert perturb_phases(p) == [((0.0, 2.5, -G), 3),  # along the wall, +y
                                 ((0.0, -2.5, -G), 3),  # along the wall, −y
                                 ((2.5, 0.0, -G), 3),  # outward from the wall, +x
                                 ((0.0, 0.0, -G), 7)]  # normal gravity: settle
    assert G == 9.81


def _free_sphere(world, position=(0.0, 0.0, 0.0)):
    """A 10 mm sphere without damping: it moves exactly as the integrator says."""
    s = pb.createMultiBody(1.0, pb.createCollisionShape(pb.GEOM_SPHERE, radius=0.01,
                                                        physicsClientId=world.cid),
                           physicsClientId=world.cid)
    pb.changeDynamics(s, -1, linearDamping=0.0, angularDamping=0.0, physicsClientId=world.cid)
    world._inertial[s] = np.eye(4)  # a primitive: its link frame is its COM frame
    world.set_pose_support(s, pose_matrix(position, [0, 0, 0, 1]))
    return s


def _set_velocity_support(world, body, linear, angular):
    r = SUPPORT_POSE_WORLD[:3, :3]
    pb.resetBaseVelocity(body, list(r @ np.asarray(linear, float)), list(r @ np.asarray(angular, float)),
                         physicsClientId=world.cid)


def _drift(n, v0, g, dt):
    """Displacement after ``n`` steps of PyBullet's semi-implicit Euler (v += g·dt, then
    x += v·dt) from velocity ``v0`` under constant gravity ``g``."""
    return np.asarray(v0, float) * n * dt + np.asarray(g, float) * dt * dt * n * (n + 1) / 2


def test_perturb_applies_each_phase_for_its_steps_in_order():
    with World(1 / 240, 50, with_floor=False) as world:
        s = _free_sphere(world)
        perturb(world, Perturbation(2.5, 3, 7, 0.01, 0.1, 11))
        dt, x, v = world.dt, np.zeros(3), np.zeros(3)
        for g, n in [((0, 2.5, -G), 3), ((0, -2.5, -G), 3), ((2.5, 0, -G), 3), ((0, 0, -G), 7)]:
            x, v = x + _drift(n, v, g, dt), v + np.asarray(g) * n * dt
        assert world.pose_support(s)[:3, 3] == pytest.approx(x, rel=1e-9, abs=1e-12)
        lin = SUPPORT_POSE_WORLD[:3, :3].T @ pb.getBaseVelocity(s, physicsClientId=world.cid)[0]
        assert lin == pytest.approx(v, rel=1e-9, abs=1e-12)
        assert x[1] > 0  # +y came first: the ±y swings do not cancel in position


# -- supporting_cluster --------------------------------------------------------------------

def test_supporting_cluster_of_one_point_is_that_point_as_a_float_copy():
    pts = np.array([[1, 2, 3]])
    c = supporting_cluster(pts, [0.0])
    assert c.dtype == np.float64 and c.tolist() == [1.0, 2.0, 3.0]
    c32 = supporting_cluster(np.array([[0.1, 0.2, 0.3]], np.float32), np.array([2.0], np.float32))
    assert c32.dtype == np.float64
    src = np.array([[0.1, 0.2, 0.3]])
    c = supporting_cluster(src, [1.0])
    c[0] = 9.0
    assert src.tolist() == [[0.1, 0.2, 0.3]]  # a copy, not a view of the input


def test_supporting_cluster_rejects_no_points():
    with pytest.raises(ValueError, match="^points: no contacts$"):
        supporting_cluster(np.zeros((0, 3)), np.zeros(0))


def test_supporting_cluster_weights_one_cluster_by_force():
    # two points 4 mm apart: one cluster, centre pulled 3/4 of the way to the 3 N point
    c = supporting_cluster([[0.0, 0.0, 0.0], [0.004, 0.0, 0.0]], [1.0, 3.0])
    assert c == pytest.approx([0.003, 0.0, 0.0], abs=1e-15)
    # forces below 1 N are weights like any other
    c = supporting_cluster([[0.0, 0.0, 0.0], [0.004, 0.0, 0.0]], [0.1, 0.3])
    assert c == pytest.approx([0.003, 0.0, 0.0], abs=1e-15)
    # no load at all: the plain centre
    c = supporting_cluster([[0.0, 0.0, 0.0], [0.004, 0.002, 0.0]], [0.0, 0.0])
    assert c == pytest.approx([0.002, 0.001, 0.0], abs=1e-15)


def test_supporting_cluster_chains_points_within_the_radius():
    # single linkage: 0–4–8 mm is one cluster (ends 8 mm apart), 20 mm is another
    pts = [[0.0, 0.0, 0.0], [0.004, 0.0, 0.0], [0.008, 0.0, 0.0], [0.020, 0.0, 0.0]]
    assert supporting_cluster(pts, [1.0, 1.0, 1.0, 2.5]) == pytest.approx([0.004, 0, 0], abs=1e-15)
    assert supporting_cluster(pts, [1.0, 0.0, 0.0, 1.5]) == pytest.approx([0.020, 0, 0], abs=1e-15)


def test_supporting_cluster_radius_boundary():
    # exactly `radius` apart (the default, 5 mm): one cluster; 0.1 mm more: two
    assert supporting_cluster([[0, 0, 0], [0.005, 0, 0]], [3.0, 1.0]) == pytest.approx([0.00125, 0, 0])
    assert supporting_cluster([[0, 0, 0], [0.0051, 0, 0]], [3.0, 1.0]).tolist() == [0, 0, 0]
    assert supporting_cluster([[0, 0, 0], [0.0051, 0, 0]], [1.0, 3.0]).tolist() == [0.0051, 0, 0]
    # an explicit radius
    assert supporting_cluster([[0, 0, 0], [0.0051, 0, 0]], [3.0, 1.0], radius=0.0051) == \
        pytest.approx([0.001275, 0, 0])
    assert supporting_cluster([[0, 0, 0], [0.004, 0, 0]], [3.0, 1.0], radius=0.0039).tolist() == [0, 0, 0]


def test_supporting_cluster_forces_decide_between_clusters_in_either_order():
    a = [[0.0, 0.0, 0.0], [0.001, 0.0, 0.0]]  # cluster A: 2 N + 2 N
    b = [[0.05, 0.0, 0.0], [0.051, 0.0, 0.001]]  # cluster B: 1 N + 2 N
    for pts, forces, want in [(a + b, [2.0, 2.0, 1.0, 2.0], [0.0005, 0, 0]),
                              (b + a, [1.0, 2.0, 2.0, 2.0], [0.0005, 0, 0]),
                              (a + b, [1.0, 1.0, 4.0, 4.0], [0.0505, 0, 0.0005]),
                              (b + a, [4.0, 4.0, 1.0, 1.0], [0.0505, 0, 0.0005])]:
        assert supporting_cluster(pts, forces) == pytest.approx(want, abs=1e-15)
    # many small forces outweigh one large one: the total decides, not the largest contact
    pts = [[0, 0, 0], [0.003, 0, 0], [0.006, 0, 0], [0.05, 0, 0]]
    assert supporting_cluster(pts, [1.0, 1.0, 1.0, 2.9]) == pytest.approx([0.003, 0, 0], abs=1e-15)


def test_supporting_cluster_tie_goes_to_the_first_cluster():
    # equal totals: the cluster fcluster labels first (the one holding the first contact)
    assert supporting_cluster([[0, 0, 0], [0.05, 0, 0]], [2.0, 2.0]).tolist() == [0, 0, 0]
    assert supporting_cluster([[0.05, 0, 0], [0, 0, 0]], [2.0, 2.0]).tolist() == [0.05, 0, 0]
    pts = [[0.05, 0, 0], [0, 0, 0], [0.051, 0, 0], [0.001, 0, 0]]
    assert supporting_cluster(pts, [1.0, 1.0, 1.0, 1.0]) == pytest.approx([0.0505, 0, 0], abs=1e-15)


def test_supporting_cluster_is_computed_in_double_precision():
    rng = np.random.default_rng(3)
    pts = rng.uniform(0.0, 0.002, (6, 3)).astype(np.float32)  # one cluster
    forces = rng.uniform(0.1, 5.0, 6).astype(np.float32)
    c = supporting_cluster(pts, forces)
    assert c.dtype == np.float64
    assert np.array_equal(c, supporting_cluster(pts.astype(float), forces.astype(float)))
    # coincident contacts average to themselves exactly, whatever the weights
    same = np.array([[1.0, 0.0, 0.0], [1.0, 0.0, 0.0]])
    assert supporting_cluster(same, np.array([1.0, 2.0 ** -24], np.float32)).tolist() == [1.0, 0, 0]


# -- observe_motion ------------------------------------------------------------------------

def test_observe_motion_measures_known_linear_and_angular_speeds():
    # another world open in the same process: observing one must not read the other
    with World(1 / 240, 50, with_floor=False) as other, World(1 / 240, 50, with_floor=False) as world:
        _free_sphere(other, (0.3, -0.2, 0.1))
        s = _free_sphere(world)
        v0, omega, n = np.array([0.3, 0.4, 0.0]), 2.0, 25
        _set_velocity_support(world, s, v0, [0.0, 0.0, omega])
        v, w = observe_motion(world, s, n)  # 10 + 10 + 5 steps
        d = _drift(n, v0, (0, 0, -G), world.dt)  # gravity is normal while observing
        duration = n * world.dt
        assert v == pytest.approx(np.linalg.norm(d) / duration, rel=1e-9)
        assert w == pytest.approx(omega, rel=1e-5)  # n·ω·dt rad over n·dt s
        # it stepped exactly n steps, no more, no fewer
        assert world.pose_support(s)[:3, 3] == pytest.approx(d, rel=1e-9, abs=1e-12)
        # one step: the speed over that single step
        world.set_pose_support(s, np.eye(4))
        _set_velocity_support(world, s, v0, [0.0, 0.0, omega])
        v, w = observe_motion(world, s, 1)
        assert v == pytest.approx(np.linalg.norm(_drift(1, v0, (0, 0, -G), world.dt)) / world.dt, rel=1e-9)
        assert w == pytest.approx(omega, rel=1e-2)  # 8 mrad: near the quaternion's resolution


def test_observe_motion_samples_every_given_steps():
    """A sphere thrown up at 1 m/s while spinning at 20 rad/s, watched for 50 steps: it rises
    and falls back (peak near step 24), and turns through more than π (the rotation angle
    comes back towards 0), so the maxima depend on which steps are sampled."""
    with World(1 / 240, 50, with_floor=False) as world:
        s = _free_sphere(world)
        n, omega, dt = 50, 20.0, world.dt

        def expected(sampled):
            dist = max(np.linalg.norm(_drift(k, (0, 0, 1.0), (0, 0, -G), dt)) for k in sampled)
            ang = max(min(k * omega * dt % (2 * np.pi), 2 * np.pi - k * omega * dt % (2 * np.pi))
                      for k in sampled)
            return dist / (n * dt), ang / (n * dt)

        for every, sampled in [(None, (10, 20, 30, 40, 50)), (1, range(1, 51)), (11, (11, 22, 33, 44, 50)),
                               (25, (25, 50)), (50, (50,)), (80, (50,))]:
            world.set_pose_support(s, np.eye(4))
            _set_velocity_support(world, s, [0.0, 0.0, 1.0], [0.0, 0.0, omega])
            got = observe_motion(world, s, n) if every is None else observe_motion(world, s, n, every)
            want = expected(sampled)
            assert got[0] == pytest.approx(want[0], rel=1e-9), every
            assert got[1] == pytest.approx(want[1], rel=1e-6), every
        world.set_pose_support(s, np.eye(4))
        _set_velocity_support(world, s, [0.0, 0.0, 1.0], [0.0, 0.0, omega])
        assert observe_motion(world, s, 0) == (0.0, 0.0)
        assert world.pose_support(s)[:3, 3].tolist() == [0.0, 0.0, 0.0]  # zero steps: not moved


# -- check_hang on boxes resting on a table ------------------------------------------------

def _box_urdf(directory, name, half, com=(0.0, 0.0, 0.0), mass=1.0) -> str:
    """A box of half extents ``half`` (its link frame at its centre), centre of mass at ``com``."""
    h = np.asarray(half, float)
    i = mass / 3 * np.array([h[1] ** 2 + h[2] ** 2, h[0] ** 2 + h[2] ** 2, h[0] ** 2 + h[1] ** 2])
    text = f"""<?xml version="1.0"?>
<robot name="{name}"><link name="base">
<inertial><origin xyz="{com[0]} {com[1]} {com[2]}"/><mass value="{mass}"/>
<inertia ixx="{i[0]}" ixy="0" ixz="0" iyy="{i[1]}" iyz="0" izz="{i[2]}"/></inertial>
<collision><geometry><box size="{2 * h[0]} {2 * h[1]} {2 * h[2]}"/></geometry></collision>
</link></robot>"""
    path = directory / f"{name}.urdf"
    path.write_text(text)
    return str(path)


#: the table: a static 10 cm cube, top face at support z = 0, spanning x 5–15 cm (off the plate)
TABLE_CENTRE = (0.1, 0.0, -0.05)


def _table_world(tmp_path, half, at=(0.1, 0.0), com=(0.0, 0.0, 0.0), friction=0.6):
    """(world, table, box): a box of half extents ``half`` lying on the table, centred at
    support (x, y) = ``at``, without damping."""
    world = World(1 / 240, 50)
    table = world.load(_box_urdf(tmp_path, "table", (0.05, 0.05, 0.05)),
                       pose_matrix(TABLE_CENTRE, [0, 0, 0, 1]), fixed=True, friction=friction)
    box = world.load(_box_urdf(tmp_path, "box", half, com), pose_matrix([at[0], at[1], half[2]], [0, 0, 0, 1]),
                     fixed=False, friction=friction, linear_damping=0.0, angular_damping=0.0)
    return world, table, box


def test_perched_reports_the_centre_of_pressure_as_the_supporting_contact(tmp_path):
    # a 4 × 4 × 2 mm block (all its contacts one cluster) with its centre of mass off-centre:
    # at rest the force-weighted contact centre lies under the centre of mass, not at the
    # middle of the footprint
    h, com = (0.002, 0.002, 0.001), (0.0015, 0.001, 0.0)
    world, table, box = _table_world(tmp_path, h, com=com)
    with world:
        world.step(60)
        check = check_hang(world, box, table, PERT)
        assert check.ok is False and check.reason == "perched"
        assert check.contact_support.shape == (3,) and check.contact_object.shape == (3,)
        assert check.contact_support[:2] == pytest.approx([0.1 + com[0], com[1]], abs=2.5e-4)
        assert check.contact_support[2] == pytest.approx(0.0, abs=1e-4)  # the table top
        # the same point in the block's frame: on its bottom face, under its centre of mass
        assert check.contact_object[:2] == pytest.approx(com[:2], abs=2.5e-4)
        assert check.contact_object[2] == pytest.approx(-h[2], abs=1e-6)
        t = world.pose_support(box)
        assert (t @ np.append(check.contact_object, 1.0))[:3] == pytest.approx(check.contact_support, abs=1e-12)
        assert world.com_support(box)[2] > check.contact_support[2]


@pytest.mark.parametrize("side", [1, -1])
def test_perched_picks_the_contact_cluster_carrying_the_most_load(tmp_path, side):
    # a 40 × 4 mm bar: its two ends touch the table in two clusters 40 mm apart; the end
    # nearer its centre of mass carries more of its weight
    world, table, box = _table_world(tmp_path, (0.02, 0.002, 0.002), com=(side * 0.012, 0.0, 0.0))
    with world:
        world.step(60)
        check = check_hang(world, box, table, PERT)
        assert check.ok is False and check.reason == "perched"
        assert check.contact_support[0] == pytest.approx(0.1 + side * 0.02, abs=1e-4)
        assert abs(check.contact_support[1]) <= 0.002 + 1e-4
        assert check.contact_object[0] == pytest.approx(side * 0.02, abs=1e-4)
        assert check.contact_object[2] == pytest.approx(-0.002, abs=1e-6)


def test_rejects_object_touching_the_robot(tmp_path):
    # a bar lying across the table's edge and a block standing for the gripper next to it
    world, table, bar = _table_world(tmp_path, (0.02, 0.005, 0.002), at=(0.15, 0.0))
    with world:
        robot = world.load(_box_urdf(tmp_path, "robot", (0.05, 0.05, 0.05)),
                           pose_matrix([0.2, 0.0, -0.05], [0, 0, 0, 1]), fixed=True, friction=0.6)
        far = world.load(_box_urdf(tmp_path, "far", (0.01, 0.01, 0.01)),
                         pose_matrix([0.1, 0.3, 0.1], [0, 0, 0, 1]), fixed=True, friction=0.6)
        world.step(30)
        state = pb.saveState(physicsClientId=world.cid)
        assert world.contacts(bar, table) and world.contacts(bar, robot)
        assert check_hang(world, bar, table, PERT, robot=robot) == HangCheck(False, "touches_robot")
        for other in (None, far):  # no robot, or one it does not touch: judged on the rest
            pb.restoreState(state, physicsClientId=world.cid)
            check = check_hang(world, bar, table, PERT, robot=other)
            assert check.ok is False and check.reason == "perched"


def _slide_and_spin(tmp_path, speed, spin):
    """A 2 cm cube on a frictionless table, sliding along +y at ``speed`` m/s and turning
    about the vertical at ``spin`` rad/s: both stay constant (no friction, no damping)."""
    world, table, box = _table_world(tmp_path, (0.01, 0.01, 0.01), at=(0.1, -0.03), friction=0.0)
    world.step(10)
    _set_velocity_support(world, box, [0.0, speed, 0.0], [0.0, 0.0, spin])
    return world, table, box


def _rest(p, speed, angular):
    return Perturbation(p.accel_m_s2, p.steps_per_direction, p.settle_steps, speed, angular,
                        p.rest_window_steps)


def test_rest_threshold_on_the_linear_speed(tmp_path):
    world, table, box = _slide_and_spin(tmp_path, 0.05, 0.0)
    with world:
        state = pb.saveState(physicsClientId=world.cid)
        v, w = observe_motion(world, box, PERT.rest_window_steps)
        assert v == pytest.approx(0.05, rel=1e-3) and w == pytest.approx(0.0, abs=1e-3)
        check = check_hang(world, box, table, _rest(PERT, 0.051, PERT.rest_angular_speed_rad_s))
        assert check.ok is False and check.reason == "perched"  # at rest: judged on the rest
        pb.restoreState(state, physicsClientId=world.cid)
        check = check_hang(world, box, table, _rest(PERT, 0.049, PERT.rest_angular_speed_rad_s))
        assert check == HangCheck(False, "not_at_rest")


def test_rest_threshold_on_the_angular_speed(tmp_path):
    world, table, box = _slide_and_spin(tmp_path, 0.0, 0.5)
    with world:
        state = pb.saveState(physicsClientId=world.cid)
        v, w = observe_motion(world, box, PERT.rest_window_steps)
        assert w == pytest.approx(0.5, rel=1e-3) and v < 1e-3
        check = check_hang(world, box, table, _rest(PERT, PERT.rest_speed_m_s, 0.51))
        assert check.ok is False and check.reason == "perched"
        pb.restoreState(state, physicsClientId=world.cid)
        check = check_hang(world, box, table, _rest(PERT, PERT.rest_speed_m_s, 0.49))
        assert check == HangCheck(False, "not_at_rest")


def test_speed_exactly_at_the_rest_threshold_counts_as_at_rest(tmp_path):
    world, table, box = _slide_and_spin(tmp_path, 0.03, 0.3)
    with world:
        state = pb.saveState(physicsClientId=world.cid)
        v, w = observe_motion(world, box, PERT.rest_window_steps)  # what check_hang will see
        for limits, reason in [((v, w), "perched"), ((np.nextafter(v, 0), w), "not_at_rest"),
                               ((v, np.nextafter(w, 0)), "not_at_rest")]:
            pb.restoreState(state, physicsClientId=world.cid)
            assert check_hang(world, box, table, _rest(PERT, *limits)).reason == reason, limits


def test_centre_of_mass_level_with_the_support_is_perched_not_hanging(tmp_path):
    # a sphere touching the table's side face touches it at its equator: its centre of mass
    # exactly level with the contact. Hanging needs it strictly below: judged at once (a
    # window of 0 steps: no motion, contacts from collision detection alone), it is perched.
    world, table, _ = _table_world(tmp_path, (0.01, 0.01, 0.01))
    with world:
        s = _free_sphere(world, (0.1, 0.05 + 0.01, -0.03125))
        pb.performCollisionDetection(physicsClientId=world.cid)
        check = check_hang(world, s, table, Perturbation(4.0, 1, 1, 0.0, 0.0, 0))
        assert check.ok is False and check.reason == "perched"
        assert check.contact_support == pytest.approx([0.1, 0.05, -0.03125], abs=1e-12)
        assert world.com_support(s)[2] == check.contact_support[2]  # level, exactly
        assert check.contact_object == pytest.approx([0.0, -0.01, 0.0], abs=1e-12)
