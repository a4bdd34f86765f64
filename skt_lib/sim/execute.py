"""One hanging trial: the Panda carries an object along an SKT, releases it, and the strict
predicate of :mod:`skt_lib.sim.hanging` judges the result (DESIGN §5).

The object is held rigidly at its grasp: the grasp target sits at ``ξ_i · T_kpt_ee`` while
the object's keypoint sits at ``ξ_i`` (paper §IV, fixed keypoint→end-effector transform).
The hold is a fixed constraint with a force limit (``grasp_force_n``), so an object pushed
into the supporting item lags behind the hand instead of passing through it; robot–object
collisions are off while it is held and on again after the release.

Sequence: start at ξ_{T-1} (set-up teleport, the only one) → follow every waypoint to ξ_0,
interpolated so that no point of the object moves more than ``step_m`` per command → hold
→ release, open the fingers, retreat along the approach axis → perturb → settle → predicate.

Outcomes (``failure_reason``, empty on success):
``ik_failed`` (the hand cannot reach the path), ``collided_before_hang`` (the object or the
robot is blocked by the support or wall on the way in; ``blocked_by`` says which),
``not_reached`` (released, it never touched the support), ``dropped`` (it touched the support, then fell), ``perched`` (resting
on top), ``touches_robot`` (still on or in the gripper).
"""

from dataclasses import dataclass, field

import numpy as np
import pybullet as pb

from skt_lib.geometry.se3 import invert, matrix_pose, pose_matrix, transform_points
from skt_lib.planning.trajectory import executed_path
from skt_lib.sim.hanging import Perturbation, check_hang, perturb_phases
from skt_lib.sim.robot import FINGER_OPEN_M, GRASP_LINK, Panda
from skt_lib.sim.world import World

REASONS = ("ik_failed", "collided_before_hang", "not_reached", "dropped", "perched",
           "touches_robot")


@dataclass(frozen=True)
class TrialSettings:
    dt: float
    solver_iterations: int
    friction: float
    robot_base: tuple[float, float, float]  # world position of the Panda base
    step_m: float  # max motion of any object point per command
    steps_per_command: int
    hold_steps: int
    track_tol_m: float  # keypoint tracking error that ends a trial
    ik_tol_m: float  # set-up IK: accepted grasp-target error
    ik_tol_rad: float
    max_joint_step_rad: float  # set-up IK: largest joint change between commands
    ik_restarts: int
    grasp_force_n: float
    retreat_m: float
    retreat_steps: int
    perturbation: Perturbation


@dataclass(frozen=True)
class TrialTask:
    trial_id: str
    method: str
    support_id: str
    object_id: str
    support_urdf: str
    object_urdf: str
    keypoint: tuple[float, ...]  # 16 floats: keypoint frame in the object frame (row-major)
    kpt_ee: tuple[float, ...]  # 16 floats: grasp target in the keypoint frame
    object_radius_m: float  # farthest object point from the keypoint
    positions: tuple[tuple[float, float, float], ...]  # SKT, support frame, ξ_0 first
    settings: TrialSettings
    record_every: int = 0  # > 0: keep a trace every this many physics steps
    extra: dict = field(default_factory=dict)  # copied into the row (difficulty, category…)


def grasp_in_keypoint(vertices: np.ndarray, keypoint: np.ndarray, pitch_deg: float,
                      band_m: float = 0.02, standoff_m: float = 0.01) -> np.ndarray:
    """Grasp target pose (4×4) in the keypoint frame: behind (−x) the lowest ``band_m`` of
    the object as it hangs, ``standoff_m`` clear of it; the approach axis is keypoint +x
    pitched down by ``pitch_deg`` (the hand comes from behind and above)."""
    v = transform_points(invert(keypoint), vertices)
    low = v[v[:, 2] <= v[:, 2].min() + band_m]
    p = np.radians(pitch_deg)
    t = np.eye(4)
    t[:3, :3] = np.array([[np.sin(p), 0.0, np.cos(p)], [0.0, -1.0, 0.0], [np.cos(p), 0.0, -np.sin(p)]])
    t[:3, 3] = [low[:, 0].min() - standoff_m, low[:, 1].mean(), low[:, 2].mean()]
    return t


class _Trace:
    """Robot link poses and the object pose every ``every`` steps, with phase names."""

    def __init__(self, world: World, robot: Panda, obj: int, every: int):
        self.world, self.robot, self.obj, self.every = world, robot, obj, every
        self.frames: list[dict] = []
        self._count = 0

    def step(self, n: int, phase: str) -> None:
        for _ in range(n):
            self.world.step(1)
            self._count += 1
            if self.every and self._count % self.every == 0:
                self.frames.append({"step": self._count, "phase": phase,
                                    "links": self.robot.link_poses(),
                                    "object": self.world.pose_support(self.obj)})


def run_trial(task: TrialTask) -> dict:
    """Run one trial in a fresh world; returns ``{"row": …, "trace": [...]}``."""
    s = task.settings
    keypoint = np.asarray(task.keypoint, float).reshape(4, 4)
    kpt_ee = np.asarray(task.kpt_ee, float).reshape(4, 4)
    path = executed_path(task.positions, s.step_m, task.object_radius_m)
    row = {"trial_id": task.trial_id, "method": task.method, "support_id": task.support_id,
           "object_id": task.object_id, **task.extra, "success": False, "failure_reason": "",
           "n_commands": len(path), "n_executed": 0, "max_track_err_m": 0.0,
           "touched_support": False, "blocked_by": ""}
    with World(s.dt, s.solver_iterations) as world:
        wall = world.add_wall()
        support = world.load(task.support_urdf, np.eye(4), fixed=True, friction=s.friction)
        obj = world.load(task.object_urdf, path[0] @ invert(keypoint), fixed=False,
                         friction=s.friction)
        robot = Panda(world, pose_matrix(s.robot_base, [0, 0, 0, 1]))
        trace = _Trace(world, robot, obj, task.record_every)
        targets = [world.to_world(xi @ kpt_ee) for xi in path]
        joints = robot.joint_path(targets, s.ik_tol_m, s.ik_tol_rad, s.max_joint_step_rad,
                                  s.ik_restarts)
        if joints is None:
            return _end(row, "ik_failed", trace)
        robot.set_collision_with(obj, False)
        world.set_pose_support(obj, path[0] @ invert(keypoint))
        row["blocked_by"] = _blockers(world, {"object": obj, "robot": robot.body},
                                      {"support": support, "wall": wall}, start=True)
        if row["blocked_by"]:
            return _end(row, "collided_before_hang", trace)
        grip = _attach(world, robot, obj, s.grasp_force_n)

        for k, (xi, q) in enumerate(zip(path, joints)):
            robot.command(q)
            trace.step(s.steps_per_command, "approach")
            err = _keypoint_error(world, obj, keypoint, xi)
            row["max_track_err_m"] = max(row["max_track_err_m"], err)
            row["n_executed"] = k + 1
            if err > s.track_tol_m:
                row["blocked_by"] = _blockers(world, {"object": obj, "robot": robot.body},
                                              {"support": support, "wall": wall})
                return _end(row, "collided_before_hang" if row["blocked_by"] else "ik_failed", trace)
        trace.step(s.hold_steps, "hold")

        pb.removeConstraint(grip, physicsClientId=world.cid)
        robot.command_fingers(FINGER_OPEN_M)
        final = robot.grasp_world()
        for i in range(1, s.retreat_steps + 1):
            back = final @ pose_matrix([0.0, 0.0, -s.retreat_m * i / s.retreat_steps], [0, 0, 0, 1])
            robot.command(robot.ik(back))
            trace.step(1, "retreat")
            row["touched_support"] |= bool(world.contacts(obj, support))
        robot.set_collision_with(obj, True)
        phases = perturb_phases(s.perturbation)
        for i, (gravity, steps) in enumerate(phases):
            world.set_gravity_support(gravity)
            trace.step(steps, "settle" if i == len(phases) - 1 else "perturb")
            row["touched_support"] |= bool(world.contacts(obj, support))
        check = check_hang(world, obj, support, robot.body)
        if check.ok:
            row["success"] = True
            return _end(row, "", trace)
        reason = {"perched": "perched", "touches_robot": "touches_robot"}.get(
            check.reason, "dropped" if row["touched_support"] else "not_reached")
        return _end(row, reason, trace)


def _attach(world: World, robot: Panda, obj: int, max_force: float) -> int:
    """Fixed constraint holding ``obj`` at its current pose relative to the grasp link
    (both frames are PyBullet's centre-of-mass frames)."""
    link = pb.getLinkState(robot.body, GRASP_LINK, computeForwardKinematics=1,
                           physicsClientId=world.cid)
    obj_pos, obj_quat = pb.getBasePositionAndOrientation(obj, physicsClientId=world.cid)
    rel = invert(pose_matrix(link[0], link[1])) @ pose_matrix(obj_pos, obj_quat)
    pos, quat = matrix_pose(rel)
    cid = pb.createConstraint(robot.body, GRASP_LINK, obj, -1, pb.JOINT_FIXED, [0, 0, 0],
                              parentFramePosition=pos, childFramePosition=[0, 0, 0],
                              parentFrameOrientation=quat, physicsClientId=world.cid)
    pb.changeConstraint(cid, maxForce=max_force, physicsClientId=world.cid)
    return cid


def _blockers(world: World, movers: dict, fixed: dict, start: bool = False) -> str:
    """``"object-wall,robot-support"``-style list of mover–obstacle pairs in contact (at the
    start: penetrating, since nothing has been stepped yet); empty when none."""
    def touching(a: int, b: int) -> bool:
        return world.min_distance(a, b) < 0.0 if start else bool(world.contacts(a, b))
    return ",".join(f"{m}-{f}" for m, a in movers.items() for f, b in fixed.items() if touching(a, b))


def _keypoint_error(world: World, obj: int, keypoint: np.ndarray, xi: np.ndarray) -> float:
    actual = world.pose_support(obj) @ keypoint
    return float(np.linalg.norm(actual[:3, 3] - xi[:3, 3]))


def _end(row: dict, reason: str, trace: _Trace) -> dict:
    row["failure_reason"] = reason
    return {"row": row, "trace": trace.frames}
