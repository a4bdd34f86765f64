"""The executor's parts (:mod:`skt_lib.sim.execute`) one at a time, on boxes written as URDFs
in tmp_path: the floating hand's anchor, the keypoint probe, the blockers a trial names, the
grasp constraint, the fallen and at-rest checks that end a trial early, and the set-up's
sweep. Each runs in a world that is not PyBullet's client 0, as a trial does beside another
world (a planner's): a call that forgets ``physicsClientId`` fails here."""

import dataclasses
import warnings
from pathlib import Path

import numpy as np
import pybullet as pb
import pytest
from scipy.spatial.transform import Rotation

from skt_lib.geometry.se3 import invert, pose_matrix
from skt_lib.sim import execute
from skt_lib.sim.hanging import Perturbation
from skt_lib.sim.robot import Panda
from skt_lib.sim.world import World
from tests.sim import scenes

DT = 1.0 / 256  # a power of two: the at-rest bounds below are exact in floats
WINDOW = 128  # at-rest window: 0.5 s
PERT = Perturbation(accel_m_s2=4.0, steps_per_direction=10, settle_steps=10, rest_speed_m_s=0.02,
                    rest_angular_speed_rad_s=0.15, rest_window_steps=WINDOW)


def box_urdf(directory: Path, name: str, size, mass: float, com=(0.0, 0.0, 0.0)) -> str:
    """A one-link box (metres, kg) with its centre of mass at ``com`` (link frame)."""
    path = Path(directory) / f"{name}.urdf"
    path.write_text(f"""<?xml version="1.0"?>
<robot name="{name}"><link name="base">
<inertial><origin xyz="{com[0]} {com[1]} {com[2]}"/><mass value="{mass}"/>
<inertia ixx="1e-4" ixy="0" ixz="0" iyy="1e-4" iyz="0" izz="1e-4"/></inertial>
<collision><geometry><box size="{size[0]} {size[1]} {size[2]}"/></geometry></collision>
</link></robot>""")
    return str(path)


def arm_urdf(directory: Path) -> str:
    """A fixed base with one child link on a fixed joint, offset and turned, its centre of
    mass off its link frame: link 0's centre-of-mass frame is nowhere near the base's."""
    path = Path(directory) / "arm.urdf"
    path.write_text("""<?xml version="1.0"?>
<robot name="arm"><link name="base">
<inertial><mass value="0"/><inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial>
<collision><geometry><box size="0.02 0.02 0.02"/></geometry></collision></link>
<link name="tip"><inertial><origin xyz="0.01 0.02 -0.015" rpy="0.3 0 0"/><mass value="0.5"/>
<inertia ixx="1e-4" ixy="0" ixz="0" iyy="1e-4" iyz="0" izz="1e-4"/></inertial>
<collision><geometry><box size="0.01 0.01 0.01"/></geometry></collision></link>
<joint name="j" type="fixed"><parent link="base"/><child link="tip"/>
<origin xyz="0.05 -0.03 0.02" rpy="0.4 -0.2 0.9"/></joint>
</robot>""")
    return str(path)


def spinner_urdf(directory: Path) -> str:
    """A fixed base with one link on a revolute joint about the base's z, the link's centre
    of mass 5 cm out along x."""
    path = Path(directory) / "spinner.urdf"
    path.write_text("""<?xml version="1.0"?>
<robot name="spinner"><link name="base">
<inertial><mass value="0"/><inertia ixx="0" ixy="0" ixz="0" iyy="0" iyz="0" izz="0"/></inertial>
</link>
<link name="arm"><inertial><origin xyz="0.05 0 0"/><mass value="1.0"/>
<inertia ixx="1e-3" ixy="0" ixz="0" iyy="1e-3" iyz="0" izz="1e-3"/></inertial></link>
<joint name="j" type="continuous"><parent link="base"/><child link="arm"/><axis xyz="0 0 1"/>
<origin xyz="0 0 0"/></joint>
</robot>""")
    return str(path)


def at(x=0.0, y=0.0, z=0.0, rotvec=(0.0, 0.0, 0.0)) -> np.ndarray:
    t = np.eye(4)
    t[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    t[:3, 3] = x, y, z
    return t


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    """(support URDF, ring URDF, ring vertices): the peg and the reference ring of
    :mod:`tests.sim.scenes`."""
    d = tmp_path_factory.mktemp("parts_scene")
    ring, vertices = scenes.build_ring(d)
    return scenes.write_support(d), ring, vertices


@pytest.fixture
def world():
    with World(DT, 50) as decoy, World(DT, 50) as w:
        assert w.cid != 0 and decoy.cid != w.cid
        yield w


def test_anchor_is_a_static_shapeless_body_where_it_is_put(world):
    n = pb.getNumBodies(physicsClientId=world.cid)
    t = at(0.1, -0.2, 0.9, rotvec=(0.3, -0.5, 1.1))
    anchor = execute._Anchor(world, t)
    assert pb.getNumBodies(physicsClientId=world.cid) == n + 1

    def pose():
        pos, quat = pb.getBasePositionAndOrientation(anchor.body, physicsClientId=world.cid)
        return pose_matrix(pos, quat)

    np.testing.assert_allclose(pose(), t, atol=1e-12)
    assert pb.getCollisionShapeData(anchor.body, -1, physicsClientId=world.cid) == ()
    assert pb.getDynamicsInfo(anchor.body, -1, physicsClientId=world.cid)[0] == 0.0  # massless
    world.step(30)  # gravity does not move it
    np.testing.assert_allclose(pose(), t, atol=1e-12)
    t2 = at(-0.3, 0.1, 1.2, rotvec=(-1.0, 0.2, 0.0))
    anchor.move(t2)
    np.testing.assert_allclose(pose(), t2, atol=1e-12)
    anchor.remove()
    assert pb.getNumBodies(physicsClientId=world.cid) == n


def test_keypoint_probe_measures_the_keypoint_not_the_centre_of_mass(world, tmp_path):
    obj = world.load(box_urdf(tmp_path, "obj", (0.04, 0.02, 0.03), 0.2, com=(0.01, -0.02, 0.005)),
                     at(0.2, 0.05, -0.1, rotvec=(0.4, 0.9, -0.3)), fixed=False, friction=0.5)
    keypoint = at(0.03, 0.0, -0.01, rotvec=(0.0, 0.0, 1.2))  # object frame
    probe = execute._KeypointProbe(world, obj, keypoint)
    xi = world.pose_support(obj) @ keypoint  # where the keypoint is, support frame
    assert probe.error(xi) < 1e-12
    off = xi.copy()
    off[:3, 3] += [0.003, -0.004, 0.012]
    assert probe.error(off) == pytest.approx(0.013, abs=1e-12)
    turned = xi @ at(rotvec=(0.0, 2.0, 0.0))  # the keypoint's position alone counts
    assert probe.error(turned) < 1e-12


def test_blockers_name_each_mover_obstacle_pair_in_order(world, tmp_path):
    wall = world.add_wall()
    support = world.load(box_urdf(tmp_path, "support", (0.02, 0.1, 0.1), 0.0), at(0.1),
                         fixed=True, friction=0.5)
    cube = box_urdf(tmp_path, "cube", (0.02, 0.02, 0.02), 0.1)
    obj = world.load(cube, at(0.005, 0.2), fixed=False, friction=0.5)  # 5 mm into the wall
    robot = world.load(cube, at(0.085), fixed=False, friction=0.5)  # 5 mm into the support
    movers, fixed = {"object": obj, "robot": robot}, {"support": support, "wall": wall}
    assert execute._blockers(world, movers, fixed, start=True) == "object-wall,robot-support"
    swapped = {"robot": robot, "object": obj}, {"wall": wall, "support": support}
    assert execute._blockers(world, *swapped, start=True) == "robot-support,object-wall"
    world.set_gravity_support((0.0, 0.0, 0.0))
    world.step(1)  # contacts exist only once stepped
    assert execute._blockers(world, movers, fixed) == "object-wall,robot-support"
    world.set_pose_support(obj, at(0.2, 0.2))  # 9 cm clear of both
    assert execute._blockers(world, movers, fixed, start=True) == "robot-support"
    world.set_pose_support(robot, at(0.2, -0.2))
    world.step(1)
    assert execute._blockers(world, movers, fixed) == ""
    assert execute._blockers(world, movers, fixed, start=True) == ""
    # moved into the support but not stepped: penetrating, yet no contact until the next step
    world.set_pose_support(robot, at(0.085))
    assert execute._blockers(world, movers, fixed, start=True) == "robot-support"
    assert execute._blockers(world, movers, fixed) == ""


@pytest.mark.parametrize("link", [-1, 0])
def test_attach_holds_the_object_where_it_is_up_to_the_force_limit(world, tmp_path, link):
    """The constraint keeps the object's pose relative to the link (centre-of-mass frames
    on both sides, neither at its link frame) against gravity; the force limit lets it go
    when set below its weight."""
    holder = (world.load(arm_urdf(tmp_path), at(0.2), fixed=True, friction=0.5) if link == 0
              else execute._Anchor(world, world.to_world(at(0.2, rotvec=(0.2, 0.1, 0.0)))).body)
    heavy = box_urdf(tmp_path, "heavy", (0.03, 0.02, 0.01), 0.5, com=(0.01, 0.0, -0.005))
    start = at(0.25, -0.02, -0.05, rotvec=(0.3, -0.2, 0.6))

    def carry(max_force: float) -> float:
        obj = world.load(heavy, start, fixed=False, friction=0.5)
        cid = execute._attach(world, holder, link, obj, max_force)
        assert pb.getConstraintInfo(cid, physicsClientId=world.cid)[10] == max_force
        world.step(120)
        moved = np.linalg.norm(world.pose_support(obj)[:3, 3] - start[:3, 3])
        pb.removeConstraint(cid, physicsClientId=world.cid)
        pb.removeBody(obj, physicsClientId=world.cid)
        return moved

    assert carry(100.0) < 2e-4  # 0.5 kg held still (not snapped to another pose)
    assert carry(0.5) > 0.01  # 0.5 N cannot hold 4.9 N: it falls


def test_attach_to_a_moving_link_keeps_the_pose_of_that_moment(world, tmp_path):
    """Attached to a link that turns at 5 rad/s, the object is carried at the pose relative
    to the link it had when attached — the link's pose then, not the one PyBullet cached
    before its last step (2 mm behind, 10 cm out at that speed)."""
    spinner = world.load(spinner_urdf(tmp_path), at(0.3), fixed=True, friction=0.5)
    obj = world.load(box_urdf(tmp_path, "obj", (0.02, 0.02, 0.02), 0.1), at(0.3, 0.1, 0.0),
                     fixed=False, friction=0.5)
    world.set_gravity_support((0.0, 0.0, 0.0))
    pb.setJointMotorControl2(spinner, 0, pb.VELOCITY_CONTROL, targetVelocity=5.0, force=500.0,
                             physicsClientId=world.cid)
    world.step(20)

    def relative() -> np.ndarray:
        link = pb.getLinkState(spinner, 0, computeForwardKinematics=1, physicsClientId=world.cid)
        body = pb.getBasePositionAndOrientation(obj, physicsClientId=world.cid)
        return invert(pose_matrix(link[0], link[1])) @ pose_matrix(*body)

    execute._attach(world, spinner, 0, obj, 1000.0)
    held = relative()  # (not before: reading the link's pose here refreshes PyBullet's cache)
    for _ in range(5):
        world.step(4)
        np.testing.assert_allclose(relative(), held, rtol=0, atol=1e-4)


def test_fallen_is_below_the_support_and_on_the_floor(tmp_path):
    """On the floor with its top below the support's bottom: fallen. Not fallen: its top
    above that bottom (though on the floor), or below it but off the floor, or no floor."""
    with World(DT, 50) as decoy, World(DT, 50) as world, World(DT, 50, with_floor=False) as bare:
        assert 0 not in (world.cid, bare.cid) and decoy.cid != world.cid
        support_z = -0.89  # support frame: the support's box spans world z 0.05 … 0.07
        cases = {}
        for name, w in (("floor", world), ("bare", bare)):
            w.set_gravity_support((0.0, 0.0, 0.0))
            support = w.load(box_urdf(tmp_path, "support", (0.02, 0.1, 0.02), 0.0),
                             at(0.1, 0.0, support_z), fixed=True, friction=0.5)
            low = w.load(box_urdf(tmp_path, "low", (0.02, 0.02, 0.049), 0.1),
                         at(0.2, 0.0, -0.95 + 0.0245), fixed=False, friction=0.5)
            tall = w.load(box_urdf(tmp_path, "tall", (0.02, 0.02, 0.051), 0.1),
                          at(0.2, 0.1, -0.95 + 0.0255), fixed=False, friction=0.5)
            floating = w.load(box_urdf(tmp_path, "floating", (0.02, 0.02, 0.02), 0.1),
                              at(0.2, -0.1, -0.95 + 0.02), fixed=False, friction=0.5)  # 1 cm up
            w.step(1)
            cases[name] = {k: execute._Fallen(w, body, support)()
                           for k, body in (("low", low), ("tall", tall), ("floating", floating))}
        assert cases["floor"] == {"low": True, "tall": False, "floating": False}
        assert cases["bare"] == {"low": False, "tall": False, "floating": False}


def test_at_rest_over_a_whole_window_within_a_quarter_of_the_bounds(world, tmp_path):
    """Sampled once per call: at rest once the last ⌈128/24⌉ + 1 = 7 samples all lie within
    a quarter of the predicate's bounds of the window's first (0.25 × 0.02 m/s × 0.5 s =
    2.5 mm; 0.25 × 0.15 rad/s × 0.5 s = 0.01875 rad; inclusive) and it touches the support."""
    support = world.load(box_urdf(tmp_path, "support", (0.04, 0.1, 0.02), 0.0), at(0.05),
                         fixed=True, friction=0.8)
    obj = world.load(box_urdf(tmp_path, "obj", (0.02, 0.02, 0.02), 0.1), at(0.05, 0.0, 0.0201),
                     fixed=False, friction=0.8)
    world.step(200)  # resting on the support's top
    assert world.contacts(obj, support)
    x0, _, z0 = pb.getBasePositionAndOrientation(obj, physicsClientId=world.cid)[0]
    dist, angle = 0.25 * 0.02 * 0.5, 0.25 * 0.15 * 0.5

    def run(samples) -> list[bool]:
        """Each sample (y offset m, turn about z rad) placed exactly, then one call; no step,
        so the contacts stay those of the resting object."""
        rest = execute._AtRest(world, obj, support, PERT)
        out = []
        for dy, turn in samples:
            quat = [0.0, 0.0, np.sin(turn / 2), np.cos(turn / 2)]
            pb.resetBasePositionAndOrientation(obj, [x0, dy, z0], quat, physicsClientId=world.cid)
            out.append(rest())
        return out

    still = [(0.0, 0.0)] * 8
    assert run(still) == [False] * 6 + [True, True]
    assert run([(0.0, 0.0), (dist / 2, 0.0)] + [(dist, 0.0)] * 5) == [False] * 6 + [True]
    assert run([(0.0, 0.0)] * 6 + [(dist * 1.01, 0.0)]) == [False] * 7
    assert run([(0.0, 0.0), (2 * dist, 0.0)] + [(0.0, 0.0)] * 5) == [False] * 7  # a jump back
    # the window slides: a first sample off, then a whole window still
    assert run([(2 * dist, 0.0)] + [(0.0, 0.0)] * 7) == [False] * 7 + [True]
    assert run([(0.0, 0.0)] + [(0.0, 0.8 * angle)] * 6) == [False] * 6 + [True]
    assert run([(0.0, 0.0)] * 6 + [(0.0, 1.2 * angle)]) == [False] * 7
    assert run([(0.0, 2 * angle)] + [(0.0, 0.0)] * 7) == [False] * 7 + [True]
    # held still at a turn whose quaternion's square rounds to 1 + 2⁻⁵²: no angle (not NaN)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert run([(0.0, 0.08)] * 7) == [False] * 6 + [True]
    quat = pb.getBasePositionAndOrientation(obj, physicsClientId=world.cid)[1]
    assert float(np.dot(quat, quat)) > 1.0  # the case at hand
    world.set_pose_support(obj, at(0.05, 0.0, 0.05))  # lifted off, stepped without gravity
    world.set_gravity_support((0.0, 0.0, 0.0))
    world.step(1)
    z0 = pb.getBasePositionAndOrientation(obj, physicsClientId=world.cid)[0][2]
    assert run(still) == [False] * 8  # still, but not on the support


def test_sweep_depth_looks_at_every_second_pose_and_the_last(world, tmp_path):
    """A 1 cm cube slid along x into a slab (x 4 … 6 cm): depth = 6.5 cm − x. The sweep sees
    poses 0, 2, 4, … and the last, not the odd ones between; with ``stop_above`` it stops at
    the first pose strictly deeper."""
    slab = world.load(box_urdf(tmp_path, "slab", (0.02, 0.1, 0.1), 0.0), at(0.05), fixed=True,
                      friction=0.5)
    obj = world.load(box_urdf(tmp_path, "cube", (0.01, 0.01, 0.01), 0.1), at(0.2), fixed=False,
                     friction=0.5)
    keypoint = at(0.0, 0.0, 0.004, rotvec=(0.0, 0.0, np.pi / 2))  # turned about z: same extents

    def path(depths_mm) -> np.ndarray:
        return np.stack([at(0.065 - d / 1000, 0.0, 0.004, rotvec=(0.0, 0.0, np.pi / 2))
                         for d in depths_mm])

    def sweep(depths_mm, **kw) -> float:
        depth = execute._sweep_depth(world, obj, invert(keypoint), path(depths_mm), [slab], **kw)
        return 1000 * depth

    assert execute.SWEEP_EVERY == 2
    assert sweep([-5, -5, -5, -5, 4, 6, -5, 3]) == pytest.approx(4, abs=1e-6)  # 5 is odd: unseen
    assert sweep([-5, -5, 1, 5, -5, -5, -5, 3]) == pytest.approx(3, abs=1e-6)  # the last one
    assert sweep([-5, -5, -5, -5, -5]) == 0.0  # clear: nothing negative comes out
    assert sweep([-5, -5, 2, -5, 5]) == pytest.approx(5, abs=1e-6)
    assert sweep([-5, -5, 2, -5, 5], stop_above=0.001) == pytest.approx(2, abs=1e-6)
    at_two = sweep([2]) / 1000
    assert sweep([-5, -5, 2, -5, 5], stop_above=at_two) == pytest.approx(5, abs=1e-6)
    assert sweep([-5, -5, 2, -5, 5], stop_above=0.006) == pytest.approx(5, abs=1e-6)


def test_a_trial_beside_another_world_decides_as_one_alone(scene):
    """The same rows whether the trial's world is PyBullet's client 0 or another world is
    open (client 0): a success, a release in the air (ended early as fallen) and a path into
    the peg, with either hand."""
    cases = [(scenes.straight_skt(), "panda", ""),
             (scenes.straight_skt(offset=(0.0, 0.12, 0.0)), "floating", "not_reached"),
             (scenes.straight_skt(offset=(0.0, 0.0, -0.009)), "panda", "collided_before_hang")]
    for positions, hand, reason in cases:
        task = scenes.ring_task(*scene, positions, hand)
        alone = execute.run_trial(task)
        with World(DT, 50) as other:
            assert other.cid == 0  # nothing else open: the trial below gets another client
            beside = execute.run_trial(task)
        assert beside["row"] == alone["row"] and beside["skt"] == alone["skt"] == 0
        assert alone["row"]["failure_reason"] == reason, alone["row"]


def _as_tuple(positions) -> tuple:
    return tuple(map(tuple, positions))


@pytest.mark.parametrize("hand", ["panda", "floating"])
@pytest.mark.parametrize("sweep", [True, False])
def test_a_fallback_runs_exactly_what_its_skt_runs_alone(scene, hand, sweep):
    """The task's own SKT starts with the ring in the peg; set-up runs the alternative, and
    the trial is the one that SKT gets as a task of its own — the same row (but the grasp's
    ``skt1/``) and the same trace: the same steps and phases, and while the hand holds the
    ring the same poses (to rounding: loading the ring at a pose and moving it there round
    differently, which after the release grows to millimetres) — swept first or not."""
    into = scenes.straight_skt(hang_s=0.03, length=0.02, offset=(0.0, 0.0, -0.009))
    clear = scenes.straight_skt()
    alone = execute.run_trial(dataclasses.replace(scenes.ring_task(*scene, clear, hand),
                                                  record_every=24))
    task = dataclasses.replace(scenes.ring_task(*scene, into, hand), record_every=24,
                               alternatives=(_as_tuple(clear),), sweep_alternatives=sweep)
    out = execute.run_trial(task)
    assert alone["row"]["success"] and out["skt"] == 1 and alone["skt"] == 0
    assert out["row"] == {**alone["row"], "grasp": "skt1/" + alone["row"]["grasp"]}
    assert len(out["trace"]) == len(alone["trace"]) > 40
    for a, b in zip(alone["trace"], out["trace"]):
        assert (a["step"], a["phase"]) == (b["step"], b["phase"])
        if a["phase"] in ("approach", "hold"):
            np.testing.assert_allclose(a["object"], b["object"], rtol=0, atol=1e-12)


@pytest.mark.parametrize("hand", ["panda", "floating"])
def test_every_skt_starting_in_the_support_or_wall_collides_at_the_start(scene, hand):
    """Every start pose penetrates (the task's in the peg, its alternative's in the wall):
    nothing runs, and the row names what the task's own start penetrates."""
    into = scenes.straight_skt(hang_s=0.03, length=0.02, offset=(0.0, 0.0, -0.009))
    # beside the wall plate (|y| ≤ 12 cm), ending with the keypoint on the wall
    wall = np.linspace([0.1, 0.2, -0.05], [0.0, 0.2, -0.05], 10)
    expect = {"success": False, "failure_reason": "collided_before_hang", "n_executed": 0,
              "blocked_by": "object-support", "detail": "object penetrates at the start pose",
              "grasp": ""}
    for alternatives in ((), (_as_tuple(wall),)):
        task = dataclasses.replace(scenes.ring_task(*scene, into, hand), alternatives=alternatives)
        out = execute.run_trial(task)
        assert {k: out["row"][k] for k in expect} == expect and out["skt"] == 0
    alone = execute.run_trial(scenes.ring_task(*scene, wall, hand))["row"]
    assert alone["blocked_by"] == "object-wall" and alone["n_executed"] == 0, alone


def test_trace_keeps_every_nth_step_with_its_phase_links_and_object(world, tmp_path):
    obj = world.load(box_urdf(tmp_path, "obj", (0.02, 0.02, 0.02), 0.1), at(0.2), fixed=False,
                     friction=0.5)  # falling: its pose differs from frame to frame
    robot = Panda(world, pose_matrix([0.15, 0.0, 0.3], [0, 0, 0, 1]))
    for hand in (None, robot):
        start = world.pose_support(obj)
        trace = execute._Trace(world, hand, obj, 3)
        assert trace.frames == [] and trace.skt == 0
        trace.step(7, "approach")
        trace.step(2, "hold")
        assert [(f["step"], f["phase"]) for f in trace.frames] == [(3, "approach"), (6, "approach"),
                                                                   (9, "hold")]
        last = trace.frames[-1]
        assert np.array_equal(last["object"], world.pose_support(obj))
        assert not np.allclose(trace.frames[0]["object"], start)
        assert not np.allclose(trace.frames[0]["object"], last["object"])
        if hand is None:
            assert all(f["links"] is None for f in trace.frames)
        else:
            assert np.array_equal(last["links"], robot.link_poses()) and len(last["links"]) > 8
        trace.step(2, "retreat")
        assert len(trace.frames) == 3  # step 11: none
    quiet = execute._Trace(world, robot, obj, 0)
    quiet.step(10, "approach")
    assert quiet.frames == []


def _phases(trace) -> dict:
    out = {}
    for f in trace:
        out[f["phase"]] = out.get(f["phase"], 0) + 1
    return out


def test_tiny_trials_rows_and_phases_by_hand(scene):
    """Whole rows of three floating-hand trials, and their traces step by step: every
    command of the executed path takes ``steps_per_command`` steps, then ``hold_steps``,
    ``retreat_steps`` and three tilts of ``steps_per_direction``; the settle, at most
    ``settle_steps``, ends on a fallen-or-rest check (every ``FALLEN_CHECK_STEPS``), as a
    fall does."""
    from skt_lib.geometry.skt import executed_path

    # tilts of 100 steps: not a multiple of FALLEN_CHECK_STEPS, so the last check of each
    # comes after a shorter stretch
    s = scenes.settings()
    pert = dataclasses.replace(s.perturbation, steps_per_direction=100)
    base = {"trial_id": "test/floating", "method": "test", "support_id": "support_test",
            "object_id": "object_reference", "difficulty": "easy", "category": "ring",
            "grasp": "pitch45_roll0"}

    def run(positions):
        task = dataclasses.replace(scenes.ring_task(*scene, positions, "floating",
                                                    perturbation=pert), record_every=1)
        out = execute.run_trial(task)
        assert [f["step"] for f in out["trace"]] == list(range(1, len(out["trace"]) + 1))
        n = len(executed_path(positions, s.step_m, scenes.RING_RADIUS_M))
        return out["row"], _phases(out["trace"]), n

    row, phases, n = run(scenes.straight_skt())
    err = row.pop("max_track_err_m")
    assert row == {**base, "success": True, "failure_reason": "", "n_commands": n,
                   "n_executed": n, "touched_support": True, "blocked_by": "", "detail": ""}
    assert 0.0 < err < 0.005 and n > 50
    settle = phases.pop("settle")
    assert phases == {"approach": n * s.steps_per_command, "hold": s.hold_steps,
                      "retreat": s.retreat_steps, "perturb": 3 * 100}
    assert 0 < settle < pert.settle_steps and settle % execute.FALLEN_CHECK_STEPS == 0

    row, phases, n = run(scenes.straight_skt(offset=(0.0, 0.12, 0.0)))  # let go in the air
    assert 0.0 < row.pop("max_track_err_m") < 0.005
    assert row == {**base, "success": False, "failure_reason": "not_reached", "n_commands": n,
                   "n_executed": n, "touched_support": False, "blocked_by": "",
                   "detail": "predicate: touches_floor"}
    perturb = phases.pop("perturb")
    assert phases == {"approach": n * s.steps_per_command, "hold": s.hold_steps,
                      "retreat": s.retreat_steps}
    assert 0 < perturb < 100 and perturb % execute.FALLEN_CHECK_STEPS == 0

    row, phases, n = run(scenes.straight_skt(offset=(0.0, 0.0, -0.009)))  # into the peg's tip
    err = row.pop("max_track_err_m")
    k = row["n_executed"]
    assert row == {**base, "success": False, "failure_reason": "collided_before_hang",
                   "n_commands": n, "n_executed": k, "touched_support": False,
                   "blocked_by": "object-support",
                   "detail": f"tracking error {1000 * err:.1f} mm at command {k}/{n}"}
    assert s.track_tol_m < err < 2 * s.track_tol_m and 0 < k < n
    assert phases == {"approach": k * s.steps_per_command}


def test_the_arm_lets_go_backs_off_along_its_approach_and_leaves(scene, monkeypatch):
    """After the hold, the gripper opens and retreats ``retreat_m`` straight back along its
    approach axis (grasp-target z), without turning; then the arm leaves the scene, so the
    perturbation and the predicate see support, wall and ring only (a hand left beside the
    hook would catch a ring swung off it); the ring stays on the peg."""
    import pybullet as pb

    from skt_lib.sim.robot import GRASP_LINK

    seen = []

    def spy(world, obj, support, p, *robot):
        bodies = [pb.getBodyUniqueId(i, physicsClientId=world.cid)
                  for i in range(pb.getNumBodies(physicsClientId=world.cid))]
        seen.append((robot, {pb.getBodyInfo(b, physicsClientId=world.cid)[1].decode()
                             for b in bodies}))
        return check_hang(world, obj, support, p, *robot)

    check_hang = execute.check_hang
    monkeypatch.setattr(execute, "check_hang", spy)
    s = scenes.settings()
    task = dataclasses.replace(scenes.ring_task(*scene, scenes.straight_skt(), "panda"),
                               record_every=1)
    out = execute.run_trial(task)
    assert out["row"]["success"], out["row"]
    assert seen == [((), {"", "object_reference", "test_support"})], seen
    by_phase = {}
    for f in out["trace"]:
        by_phase.setdefault(f["phase"], []).append(f)
    base = out["trace"][0]["links"][0]  # the base's centre-of-mass frame: above its origin
    assert np.allclose(base[:3, :3], np.eye(3), atol=1e-12)  # unturned, where put
    assert np.allclose(base[:2, 3], s.robot_base[:2], atol=1e-12)
    released = by_phase["hold"][-1]["links"][GRASP_LINK + 1]
    rel = np.linalg.inv(released) @ by_phase["retreat"][-1]["links"][GRASP_LINK + 1]
    assert -s.retreat_m - 1e-4 < rel[2, 3] < -0.07
    assert np.linalg.norm(rel[:2, 3]) < 1e-3 and np.allclose(rel[:3, :3], np.eye(3), atol=1e-4)
    assert len(by_phase["retreat"]) == s.retreat_steps
    assert all(f["links"] is not None for f in by_phase["retreat"])
    after = by_phase["perturb"] + by_phase["settle"]
    assert after and all(f["links"] is None for f in after)


def test_a_trial_without_grasp_candidates_is_refused(scene):
    task = dataclasses.replace(scenes.ring_task(*scene, scenes.straight_skt()), grasps=())
    with pytest.raises(ValueError, match=r"^test/panda: no grasp candidates$"):
        execute.run_trial(task)


def test_a_float32_keypoint_is_widened_first(scene):
    """A keypoint of numpy float32 values (a turned frame, so products round) runs the trial
    its float64 values run, to the bit."""
    from skt_lib.sim.grasp import grasp_candidates

    support, ring, vertices = scene
    keypoint = scenes.RING_KEYPOINT.copy()
    keypoint[:3, :3] = keypoint[:3, :3] @ Rotation.from_rotvec([0.05, -0.03, 0.02]).as_matrix()
    narrow = keypoint.astype(np.float32)
    grasps = grasp_candidates(vertices, narrow.astype(float), (45.0,), (0.0,))
    task = dataclasses.replace(scenes.ring_task(*scene, scenes.straight_skt(), "floating"),
                               grasps=grasps)
    rows = [execute.run_trial(dataclasses.replace(task, keypoint=k))["row"]
            for k in (tuple(narrow.ravel()), tuple(narrow.astype(float).ravel().tolist()))]
    assert rows[0] == rows[1] and rows[0]["success"], rows


@pytest.mark.parametrize("hand,executor", [("panda", "rest_exit"), ("floating", "rest_exit"),
                                           ("floating", "reference")])
def test_released_at_the_pegs_tip_it_touches_then_drops(scene, hand, executor):
    """Let go 1 cm past the tip, the ring touches the peg during the retreat and falls to
    the floor: dropped, not not_reached — whether the trial ends as soon as it lies there or
    (the reference) runs the whole perturbation, where it no longer touches the peg."""
    task = scenes.ring_task(*scene, scenes.straight_skt(hang_s=0.1), hand, executor=executor)
    out = execute.run_trial(dataclasses.replace(task, record_every=1))
    row = out["row"]
    assert (row["failure_reason"], row["touched_support"], row["detail"]) == (
        "dropped", True, "predicate: touches_floor"), row
    perturbed = sum(f["phase"] == "perturb" for f in out["trace"])
    assert (perturbed == 720) if executor == "reference" else (perturbed < 240)


def test_out_of_reach_names_the_set_ups_failure_and_the_fallbacks_tried(scene):
    far = scenes.straight_skt(offset=(0.0, 1.5, 0.0))
    alone = execute.run_trial(scenes.ring_task(*scene, far))["row"]
    assert alone["detail"].startswith("no reachable grasp (6 tried: 6 unreachable_hang)")
    assert "further" not in alone["detail"]
    task = dataclasses.replace(scenes.ring_task(*scene, far), alternatives=(_as_tuple(far),))
    both = execute.run_trial(task)["row"]
    assert both["detail"] == alone["detail"] + "; nor on any of 1 further SKTs"
    assert both["failure_reason"] == alone["failure_reason"] == "ik_failed"


def _motion(trace, phase: str) -> tuple[float, float]:
    """Distance the object's frame travelled and angle it turned over a phase (m, rad)."""
    poses = np.stack([f["object"] for f in trace if f["phase"] == phase])
    dist = np.linalg.norm(np.diff(poses[:, :3, 3], axis=0), axis=1).sum()
    rel = np.einsum("nji,njk->nik", poses[:-1, :3, :3], poses[1:, :3, :3])
    turn = np.arccos(np.clip((np.trace(rel, axis1=1, axis2=2) - 1) / 2, -1, 1)).sum()
    return float(dist), float(turn)


def test_the_objects_damping_is_its_own_while_perturbed_and_while_settling(scene):
    """Raise the object's linear or angular damping (from PyBullet's 0.04) and the hung ring
    moves or turns less while perturbed; lower its settle damping and it takes longer to
    come to rest — each number reaches the object."""
    def run(**changes):
        task = scenes.ring_task(*scene, scenes.straight_skt(), "floating", **changes)
        out = execute.run_trial(dataclasses.replace(task, record_every=1))
        assert out["row"]["success"], out["row"]
        settle = sum(f["phase"] == "settle" for f in out["trace"])
        return _motion(out["trace"], "perturb"), settle

    (dist, turn), settle = run()
    (dist_lin, _), _ = run(linear_damping=2.0)
    (_, turn_ang), _ = run(angular_damping=2.0)
    assert dist_lin < 0.9 * dist and turn_ang < 0.7 * turn
    assert run(settle_angular_damping=0.04)[1] > settle  # default 5 /s
    assert run(settle_linear_damping=5.0)[1] != settle  # default 1 /s


def test_the_support_is_fixed_even_with_a_mass(scene, tmp_path):
    """The executor fixes the support's base: one whose URDF gives it 2 kg (where a massless
    one would stay put by itself) decides the same trial as the massless one."""
    support, ring, vertices = scene
    text = Path(support).read_text()
    assert text.count('<mass value="0"/>') == 1
    heavy = tmp_path / "heavy_support.urdf"
    heavy.write_text(text.replace('<mass value="0"/><inertia ixx="0" ixy="0" ixz="0" iyy="0" '
                                  'iyz="0" izz="0"/>', '<mass value="2"/><inertia ixx="0.01" '
                                  'ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/>'))
    assert heavy.read_text() != text
    task = scenes.ring_task(support, ring, vertices, scenes.straight_skt(), "floating")
    rows = [execute.run_trial(dataclasses.replace(task, support_urdf=u))["row"]
            for u in (support, str(heavy))]
    assert rows[0] == rows[1] and rows[0]["success"]


def test_with_no_grasp_on_any_skt_the_row_gives_the_tasks_own_failure(scene):
    """Set-up finds no grasp on any SKT: the row describes the task's own SKT's failure —
    even when a clear alternative was tried before it (an IK tolerance nothing meets; the
    two failures differ in their error) — or, where the task's own start penetrates the peg
    (never set up), the first one tried."""
    def detail(positions, alternatives=(), **changes):
        task = dataclasses.replace(scenes.ring_task(*scene, positions, **changes),
                                   alternatives=tuple(map(_as_tuple, alternatives)))
        row = execute.run_trial(task)["row"]
        assert row["failure_reason"] == "ik_failed" and row["n_executed"] == 0, row
        return row["detail"]

    into, clear = scenes.straight_skt(offset=(0.0, 0.0, -0.009)), scenes.straight_skt()
    own, other = detail(into, ik_tol_m=1e-7), detail(clear, ik_tol_m=1e-7)
    assert own != other
    assert detail(into, [clear], ik_tol_m=1e-7) == own + "; nor on any of 1 further SKTs"
    start_in = scenes.straight_skt(hang_s=0.03, length=0.02, offset=(0.0, 0.0, -0.009))
    far = scenes.straight_skt(offset=(0.0, 1.5, 0.0))
    assert detail(start_in, [far]) == detail(far) + "; nor on any of 1 further SKTs"


def _approach_commands(monkeypatch, task):
    """Run ``task`` (Panda); returns (the set-up's joint path, every arm command from the
    grasp to the release, the row, the trace's approach steps)."""
    calls, holding, chosen = [], [False], {}
    command, fingers = Panda.command, Panda.command_fingers
    attach, choose = execute._attach, execute.choose_grasp

    def record(self, q):
        if holding[0]:
            calls.append(np.array(q, float))
        command(self, q)

    def grip(*args, **kwargs):
        holding[0] = True
        return attach(*args, **kwargs)

    def release(self, width):  # the fingers open at the release
        holding[0] = False
        fingers(self, width)

    def pick(*args, **kwargs):
        chosen["c"] = choose(*args, **kwargs)
        return chosen["c"]

    monkeypatch.setattr(Panda, "command", record)
    monkeypatch.setattr(Panda, "command_fingers", release)
    monkeypatch.setattr(execute, "_attach", grip)
    monkeypatch.setattr(execute, "choose_grasp", pick)
    out = execute.run_trial(dataclasses.replace(task, record_every=1))
    steps = sum(f["phase"] == "approach" for f in out["trace"])
    return np.asarray(chosen["c"].joints), np.stack(calls), out["row"], steps


@pytest.mark.parametrize("step_m", [0.002, 0.02])
def test_the_arm_never_moves_a_joint_faster_than_its_limit(scene, monkeypatch, step_m):
    """Every command of the approach is within the Panda's joint velocity limits (URDF) of the
    one before, over ``steps_per_command`` steps: a faster step of the set-up's path is split
    into sub-commands on the straight joint-space line, the path's own configurations among
    them; where the path keeps within the limits it runs command for command as planned."""
    task = scenes.ring_task(*scene, scenes.straight_skt(), "panda", step_m=step_m,
                            steps_per_command=1)
    joints, calls, row, steps = _approach_commands(monkeypatch, task)
    s = task.settings
    with World(s.dt, 50) as w:
        limit = Panda(w, np.eye(4)).max_velocity * s.steps_per_command * s.dt
    assert np.allclose(limit, [2.175 * s.dt] * 4 + [2.61 * s.dt] * 3)
    assert row["success"], row
    assert (np.abs(np.diff(calls, axis=0)) <= limit * (1 + 1e-12)).all()
    assert np.array_equal(calls[0], joints[0])  # the arm starts where the set-up put it
    # the planned configurations are commanded, in order, each one exactly; between two,
    # the fewest sub-commands that keep the limit, evenly on the straight joint-space line
    at = [next(i for i in range(len(calls)) if np.array_equal(calls[i], q)) for q in joints]
    assert at == sorted(at) and at[-1] == len(calls) - 1
    for k in range(1, len(joints)):
        n = at[k] - at[k - 1]
        assert n == max(1, int(np.ceil((np.abs(joints[k] - joints[k - 1]) / limit).max())))
        line = joints[k - 1] + np.outer(np.arange(1, n + 1) / n, joints[k] - joints[k - 1])
        assert np.allclose(calls[at[k - 1] + 1:at[k] + 1], line, rtol=0, atol=1e-12)
    assert steps == len(calls) * s.steps_per_command
    fast = (np.abs(np.diff(joints, axis=0)) > limit).any(axis=1).sum()
    if step_m == 0.002:
        assert fast == 0 and len(calls) == len(joints)  # nothing to split
    else:
        assert fast > 0 and len(calls) > len(joints)
