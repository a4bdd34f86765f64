"""One hanging trial: a hand carries an object along an SKT, releases it, and the strict
predicate of :mod:`skt_lib.sim.hanging` judges the result (docs/design.md §5).

The object is held rigidly at its grasp: the grasp target sits at ``ξ_i · T_kpt_ee`` while
the object's keypoint sits at ``ξ_i`` (paper §IV, fixed keypoint→end-effector transform).
The hold is a fixed constraint with a force limit (``grasp_force_n``), so an object pushed
into the supporting item lags behind the hand instead of passing through it.

Two hands (``TrialTask.hand``):

- ``panda``: the Franka Panda. At set-up the grasp is chosen from the task's candidates
  (:func:`skt_lib.sim.grasp.choose_grasp`: the first for which the IK finds a joint path
  along the whole executed path, the arm clear of support and wall along it and of the
  object at the start); robot–object
  collisions are off while the object is held and on from the release. Where no candidate
  follows the SKT, set-up tries the task's ``alternatives`` (further SKTs of the same
  support: the oracle's other stored SKTs, or a checked learned method's other candidates)
  in order — the oracle's swept-clear ones first — skipping one whose start pose the
  object penetrates, and runs the first that has a grasp (``grasp`` is then prefixed
  ``skt<k>/``).
- ``floating``: no arm; a massless, collision-free kinematic anchor at the grasp target
  (first candidate grasp) is moved to each command pose, with the same hold constraint; at
  the release it is removed, so it cannot hold the object.

Sequence: start at ξ_{T-1} (set-up teleport, the only one) → follow every pose of
:func:`skt_lib.geometry.skt.executed_path` to ξ_0 (no object point moves more than
``step_m`` per command), checking the keypoint tracking error after every command; the
Panda's joints move within their velocity limits (the URDF's: 2.175 rad/s for joints 1–4,
2.61 for 5–7): a command whose joint step would be faster over its ``steps_per_command``
steps is preceded by sub-commands on the straight joint-space line from the one before, as
many as that takes (a command within the limits runs as it is) → hold →
release: constraint removed, fingers open, robot–object collisions on, retreat along the
approach axis, then the arm is taken out of the scene (it would otherwise stand beside the
hook, and its hand catch an object the perturbation swings off) → perturb (the object at
``linear_damping``/``angular_damping``: PyBullet's default 0.04 in the committed params, as
the anchors') → settle (at the ``settle_*`` damping: an undamped hung object keeps swinging)
→ predicate.

Three executors (``TrialSettings.executor``, :data:`EXECUTORS`) decide the same way and differ
in the physics steps they skip where the verdict is already certain; ``make bench`` times
them against each other on the same trials, verdict by verdict:

- ``reference``: numpy IK, the Panda's visual meshes loaded, every physics step;
- ``fallen_exit``: the compiled IK, no visual meshes, and a released object that lies on the
  floor wholly below the supporting item has fallen for good (:class:`_Fallen`): the trial
  ends there with the predicate's ``touches_floor`` instead of running the rest of the
  perturbation;
- ``rest_exit`` (the default): also ends the settle once the object, touching the support,
  has kept within :data:`REST_EXIT_FRACTION` of the predicate's at-rest bounds over a whole
  window (:class:`_AtRest`); the predicate then observes it for its own window as always.

Outcomes (``failure_reason``, empty on success; :data:`REASONS`):

- ``ik_failed``: no reachable grasp at set-up (``detail`` says which check failed:
  ``unreachable_hang``, ``tracking_tolerance``, ``joint_jump``, or ``clearance``: the arm
  touches support or wall along the path, or the object at the start), or a tracking error above ``track_tol_m`` during execution with neither the
  object nor the robot touching support or wall;
- ``collided_before_hang``: the object penetrates support or wall at the start pose, or a
  tracking error during execution while the object or robot touches them (``blocked_by``
  lists the pairs, e.g. ``object-support,robot-wall``);
- ``not_reached``: released, it never touched the support;
- ``dropped``: it touched the support after the release, but ended off it (floor, or no contact);
- ``not_at_rest``: on the support but still moving at the end (swinging, sliding off);
- ``on_wall_plate``: resting only on the support's wall plate, not on its hanging part;
- ``perched``: resting on top of the support (centre of mass above the supporting contact).

An object the retreating hand drags off the hook fails as ``dropped`` or ``not_reached``:
the arm is gone before the perturbation, so none ends on the gripper.
"""

from dataclasses import dataclass, field

import numpy as np
import pybullet as pb

from skt_lib.geometry.se3 import invert, matrix_pose, pose_matrix
from skt_lib.geometry.skt import executed_path
from skt_lib.sim.grasp import Grasp, GraspChoice, GraspFailure, choose_grasp
from skt_lib.sim.hanging import Perturbation, check_hang, perturb_phases
from skt_lib.sim.robot import FINGER_OPEN_M, GRASP_LINK, Panda
from skt_lib.sim.world import World

REASONS = ("ik_failed", "collided_before_hang", "not_reached", "dropped", "not_at_rest",
           "on_wall_plate", "perched")
HANDS = ("panda", "floating")
#: The executors, slowest first: ``reference`` (numpy IK, the Panda's visual meshes, every
#: physics step), ``fallen_exit`` (compiled IK, no visual meshes; ends a trial once the object
#: has fallen for good) and ``rest_exit`` (also ends the settle once the object is at rest).
EXECUTORS = ("reference", "fallen_exit", "rest_exit")
#: predicate reason → trial reason; "touches_floor"/"no_contact" depend on a support touch
_HANG_REASON = {"perched": "perched", "not_at_rest": "not_at_rest",
                "on_wall_plate": "on_wall_plate"}


@dataclass(frozen=True)
class TrialSettings:
    dt: float
    solver_iterations: int
    friction: float
    linear_damping: float  # of the object, 1/s (World.load): carried, released, perturbed
    angular_damping: float  # of the object, 1/s
    settle_linear_damping: float  # of the object during the final settle only, 1/s
    settle_angular_damping: float
    robot_base: tuple[float, float, float]  # world position of the Panda base, m
    step_m: float  # max motion of any object point per command
    steps_per_command: int
    hold_steps: int
    track_tol_m: float  # keypoint tracking error that ends a trial
    ik_tol_m: float  # set-up IK: accepted grasp-target error
    ik_tol_rad: float
    max_joint_step_rad: float  # set-up IK: largest joint change between commands
    ik_restarts: int  # set-up IK: start configurations per grasp candidate
    setup_clearance_m: float  # set-up: least robot distance to support, wall, object
    grasp_force_n: float
    retreat_m: float
    retreat_steps: int
    perturbation: Perturbation
    #: which executor (:data:`EXECUTORS`; module docs): ``make bench`` times them against
    #: each other on the same trials, verdict by verdict
    executor: str = "rest_exit"


@dataclass(frozen=True)
class TrialTask:
    trial_id: str
    method: str
    support_id: str
    object_id: str
    support_urdf: str
    object_urdf: str
    keypoint: tuple[float, ...]  # 16 floats: keypoint frame in the object frame (row-major)
    grasps: tuple[Grasp, ...]  # grasp candidates, in the order they are tried
    object_radius_m: float  # farthest object point from the keypoint
    positions: tuple[tuple[float, float, float], ...]  # SKT, support frame, ξ_0 first
    settings: TrialSettings
    record_every: int = 0  # > 0: keep a trace every this many physics steps
    extra: dict = field(default_factory=dict)  # copied into the row (difficulty, category…)
    hand: str = "panda"  # "panda" | "floating"
    #: further SKTs (same layout as ``positions``) the Panda's set-up may fall back to, in
    #: order, when no grasp follows ``positions`` (the oracle: the support's other stored SKTs;
    #: a checked learned method: the cloud check's other candidates)
    alternatives: tuple[tuple[tuple[float, float, float], ...], ...] = ()
    #: set-up tries first the SKTs along which the object, swept kinematically through the
    #: simulated support, stays clear (the oracle's, privileged); ``False``: in the given order
    sweep_alternatives: bool = True


class _Trace:
    """Robot link poses (``None`` without a robot, and once the arm has left after the
    retreat) and the object pose every ``every`` steps, with phase names."""

    def __init__(self, world: World, robot: Panda | None, obj: int, every: int):
        self.world, self.robot, self.obj, self.every = world, robot, obj, every
        self.frames: list[dict] = []
        self.skt = 0  # which SKT ran: 0 the task's, k > 0 its k-th alternative
        self._count = 0

    def step(self, n: int, phase: str) -> None:
        for _ in range(n):
            self.world.step(1)
            self._count += 1
            if self.every and self._count % self.every == 0:
                self.frames.append({"step": self._count, "phase": phase,
                                    "links": None if self.robot is None else self.robot.link_poses(),
                                    "object": self.world.pose_support(self.obj)})


class _Anchor:
    """The floating hand: a massless body without collision shape, teleported to each
    commanded grasp-target pose (world frame)."""

    def __init__(self, world: World, t_world: np.ndarray):
        self.cid = world.cid
        pos, quat = matrix_pose(t_world)
        self.body = pb.createMultiBody(0.0, -1, -1, pos, quat, physicsClientId=self.cid)

    def move(self, t_world: np.ndarray) -> None:
        pos, quat = matrix_pose(t_world)
        pb.resetBasePositionAndOrientation(self.body, pos, quat, physicsClientId=self.cid)

    def remove(self) -> None:
        pb.removeBody(self.body, physicsClientId=self.cid)


def run_trial(task: TrialTask) -> dict:
    """Run one trial in a fresh world; returns ``{"row": …, "trace": [...]}`` (row: schema
    ``trials``)."""
    s = task.settings
    if task.hand not in HANDS:
        raise ValueError(f"hand: expected one of {HANDS}, got {task.hand!r}")
    if s.executor not in EXECUTORS:
        raise ValueError(f"executor: expected one of {EXECUTORS}, got {s.executor!r}")
    reference = s.executor == "reference"
    if not task.grasps:
        raise ValueError(f"{task.trial_id}: no grasp candidates")
    keypoint = np.asarray(task.keypoint, float).reshape(4, 4)
    path = executed_path(task.positions, s.step_m, task.object_radius_m)  # the object's start
    row = {"trial_id": task.trial_id, "method": task.method, "support_id": task.support_id,
           "object_id": task.object_id, **task.extra, "success": False, "failure_reason": "",
           "n_commands": len(path), "n_executed": 0, "max_track_err_m": 0.0,
           "touched_support": False, "blocked_by": "", "grasp": "", "detail": ""}
    with World(s.dt, s.solver_iterations) as world:
        wall = world.add_wall()
        support = world.load(task.support_urdf, np.eye(4), fixed=True, friction=s.friction)
        obj = world.load(task.object_urdf, path[0] @ invert(keypoint), fixed=False,
                         friction=s.friction, linear_damping=s.linear_damping,
                         angular_damping=s.angular_damping)
        fixed = {"support": support, "wall": wall}
        if task.hand == "panda":
            robot = Panda(world, pose_matrix(s.robot_base, [0, 0, 0, 1]), compiled=not reference,
                          visual=reference)

            def setup(p: np.ndarray) -> GraspChoice | GraspFailure:
                return choose_grasp(world, robot, p, task.grasps, [support, wall], obj, s.ik_tol_m,
                                    s.ik_tol_rad, s.max_joint_step_rad, s.ik_restarts,
                                    s.setup_clearance_m)
        else:
            robot, setup = None, None
        trace = _Trace(world, robot, obj, task.record_every)
        ran, path, choice = _choose_skt(world, task, keypoint, obj, fixed, path, setup)
        trace.skt = ran
        if choice is None:  # every SKT starts with the object in the support or wall
            row["blocked_by"] = _blockers(world, {"object": obj}, fixed, start=True)
            row["detail"] = "object penetrates at the start pose"
            return _end(row, "collided_before_hang", trace)
        prefix = f"skt{ran}/" if ran else ""
        row["n_commands"] = len(path)
        if robot is not None:
            if isinstance(choice, GraspFailure):
                row["detail"] = choice.describe() + (
                    f"; nor on any of {len(task.alternatives)} further SKTs"
                    if task.alternatives else "")
                return _end(row, "ik_failed", trace)
            row["grasp"] = prefix + choice.grasp.label
            kpt_ee, joints = choice.grasp.matrix(), choice.joints
            robot.set_collision_with(obj, False)
            grip = _attach(world, robot.body, GRASP_LINK, obj, s.grasp_force_n)
            movers = {"object": obj, "robot": robot.body}

            # joint motion per command at the Panda's velocity limits: a faster step is
            # split into sub-commands along the straight joint-space line
            per_command = robot.max_velocity * s.steps_per_command * s.dt

            def command(k: int) -> None:
                n = 1 if k == 0 else int(np.ceil((np.abs(joints[k] - joints[k - 1])
                                                  / per_command).max()))
                for i in range(1, n):
                    robot.command(joints[k - 1] + (joints[k] - joints[k - 1]) * (i / n))
                    trace.step(s.steps_per_command, "approach")
                robot.command(joints[k])
        else:
            grasp = task.grasps[0]
            row["grasp"] = prefix + grasp.label
            kpt_ee = grasp.matrix()
            anchor = _Anchor(world, world.to_world(path[0] @ kpt_ee))
            grip = _attach(world, anchor.body, -1, obj, s.grasp_force_n)
            movers = {"object": obj}

            def command(k: int) -> None:
                anchor.move(world.to_world(path[k] @ kpt_ee))

        probe = _KeypointProbe(world, obj, keypoint)
        for k, xi in enumerate(path):
            command(k)
            trace.step(s.steps_per_command, "approach")
            err = probe.error(xi)
            row["max_track_err_m"] = max(row["max_track_err_m"], err)
            row["n_executed"] = k + 1
            if err > s.track_tol_m:
                row["blocked_by"] = _blockers(world, movers, fixed)
                row["detail"] = f"tracking error {1000 * err:.1f} mm at command {k + 1}/{len(path)}"
                return _end(row, "collided_before_hang" if row["blocked_by"] else "ik_failed", trace)
        trace.step(s.hold_steps, "hold")

        pb.removeConstraint(grip, physicsClientId=world.cid)
        if robot is not None:
            robot.command_fingers(FINGER_OPEN_M)
            robot.set_collision_with(obj, True)  # from the release: the hand can knock it off
            final = robot.grasp_world()
            for i in range(1, s.retreat_steps + 1):
                back = final @ pose_matrix([0.0, 0.0, -s.retreat_m * i / s.retreat_steps], [0, 0, 0, 1])
                robot.command(robot.ik(back))
                trace.step(1, "retreat")
                row["touched_support"] |= bool(world.contacts(obj, support))
            # the arm leaves the scene: left standing 8 cm away, its hand would catch an
            # object swinging off the hook in the perturbation and hold it up (docs/evaluation.md)
            pb.removeBody(robot.body, physicsClientId=world.cid)
            robot = trace.robot = None
        else:
            anchor.remove()
            for _ in range(s.retreat_steps):
                trace.step(1, "retreat")
                row["touched_support"] |= bool(world.contacts(obj, support))
        phases = perturb_phases(s.perturbation)
        fallen = None if reference else _Fallen(world, obj, support)
        for i, (gravity, steps) in enumerate(phases):
            settle = i == len(phases) - 1
            if settle:  # the settle may damp (docs/design.md §5); the perturbation does not
                pb.changeDynamics(obj, -1, linearDamping=s.settle_linear_damping,
                                  angularDamping=s.settle_angular_damping, physicsClientId=world.cid)
            world.set_gravity_support(gravity)
            rest = (_AtRest(world, obj, support, s.perturbation)
                    if settle and s.executor == "rest_exit" else None)
            chunk = steps if fallen is None else FALLEN_CHECK_STEPS
            for done in range(0, steps, chunk):
                trace.step(min(chunk, steps - done), "settle" if settle else "perturb")
                if fallen is not None and fallen():  # the predicate would say touches_floor
                    row["detail"] = "predicate: touches_floor"
                    return _end(row, "dropped" if row["touched_support"] else "not_reached", trace)
                if rest is not None and rest():  # the rest of the settle would not move it
                    break
            row["touched_support"] |= bool(world.contacts(obj, support))
        check = check_hang(world, obj, support, s.perturbation)  # no hand is left
        if check.ok:
            row["success"] = True
            return _end(row, "", trace)
        row["detail"] = f"predicate: {check.reason}"
        reason = _HANG_REASON.get(check.reason, "dropped" if row["touched_support"] else "not_reached")
        return _end(row, reason, trace)


#: Set-up with alternatives (the oracle's): an SKT along which the object, swept
#: kinematically, penetrates support or wall deeper than this (m) is tried only after those
#: it does not; the sweep looks at every ``SWEEP_EVERY``-th pose of the executed path.
SWEEP_TOL_M = 0.002
SWEEP_EVERY = 2


def _choose_skt(world: World, task: TrialTask, keypoint: np.ndarray, obj: int, fixed: dict,
                path: np.ndarray, setup) -> tuple[int, np.ndarray,
                                                   GraspChoice | GraspFailure | bool | None]:
    """Which SKT a trial runs: ``(k, its executed path, set-up)`` — ``k`` 0 for the task's
    own SKT (executed ``path``), ``k`` > 0 for its k-th alternative; set-up: the
    :class:`GraspChoice` (Panda, ``setup`` given), ``True`` (floating hand), the
    :class:`GraspFailure` of the task's own SKT (else of the first tried) when no SKT has a
    grasp, or ``None`` when every SKT starts with the object in the support or wall. Leaves
    the object at the chosen path's start.

    Without alternatives: the task's SKT. With them: the SKTs whose sweep of the object is
    clear (:data:`SWEEP_TOL_M`) first, in order, then the others from the shallowest deepest
    penetration on (ties in order) — or, without ``task.sweep_alternatives``, every SKT in
    order, unswept; the first whose start pose the object does not penetrate and (Panda)
    that a grasp candidate follows."""
    s = task.settings
    inv = invert(keypoint)
    paths = {0: path}  # executed paths, made when first needed: most trials need one

    def path_of(k: int) -> np.ndarray:
        if k not in paths:
            paths[k] = executed_path(task.alternatives[k - 1], s.step_m, task.object_radius_m)
        return paths[k]

    bodies = list(fixed.values())
    failures = {}

    def attempt(k: int):
        if task.alternatives:  # a sweep moved it; else it still stands where it was loaded
            world.set_pose_support(obj, path_of(k)[0] @ inv)
        if _blockers(world, {"object": obj}, fixed, start=True):
            return None
        if setup is None:
            return k, path_of(k), True
        choice = setup(path_of(k))
        if not isinstance(choice, GraspFailure):
            return k, path_of(k), choice
        failures[k] = choice
        return None

    # swept lazily, in the order the docstring gives: a clear SKT is tried as soon as its
    # sweep is known clear; the others are swept to their deepest only when none was taken
    penetrating = []
    sweep = task.alternatives and task.sweep_alternatives
    for k in range(1 + len(task.alternatives)):
        if sweep and _sweep_depth(world, obj, inv, path_of(k), bodies,
                                  stop_above=SWEEP_TOL_M) > SWEEP_TOL_M:
            penetrating.append(k)
            continue
        if (out := attempt(k)) is not None:
            return out
    depth = {k: _sweep_depth(world, obj, inv, path_of(k), bodies) for k in penetrating}
    for k in sorted(penetrating, key=lambda k: (depth[k], k)):
        if (out := attempt(k)) is not None:
            return out
    if not failures:
        if task.alternatives:  # back at the task's own start, for the blockers the row names
            world.set_pose_support(obj, paths[0][0] @ inv)
        return 0, paths[0], None
    return 0, paths[0], failures.get(0, next(iter(failures.values())))


def _sweep_depth(world: World, obj: int, inv_keypoint: np.ndarray, path: np.ndarray,
                 bodies, stop_above: float = np.inf) -> float:
    """The deepest the object, placed along ``path`` (keypoint frames), penetrates any of
    ``bodies`` (m, ≥ 0; kinematic; at every :data:`SWEEP_EVERY`-th pose and the last); or,
    as soon as a pose goes deeper than ``stop_above``, that pose's depth."""
    deepest = 0.0
    for k in [*range(0, len(path), SWEEP_EVERY), len(path) - 1]:
        world.set_pose_support(obj, path[k] @ inv_keypoint)
        deepest = max(deepest, *(-world.min_distance(obj, b, 0.0) for b in bodies))
        if deepest > stop_above:
            break
    return deepest


#: Physics steps between two checks whether a released object has fallen for good.
FALLEN_CHECK_STEPS = 24


class _Fallen:
    """Whether a released object has fallen for good: it lies on the floor, wholly below the
    supporting item. Nothing in the rest of a trial lifts it again (gravity always points
    down; the arm has retreated), so the predicate's verdict is certain — ``touches_floor`` —
    and the rest of the perturbation can be skipped (the reference executor runs it all)."""

    def __init__(self, world: World, obj: int, support: int):
        self.world, self.obj = world, obj
        self.bottom = pb.getAABB(support, -1, physicsClientId=world.cid)[0][2]

    def __call__(self) -> bool:
        w = self.world
        top = pb.getAABB(self.obj, -1, physicsClientId=w.cid)[1][2]
        return top < self.bottom and w.floor is not None and bool(w.contacts(self.obj, w.floor))


#: ``rest_exit`` ends the settle once the object, touching the support, has stayed within
#: this fraction of the predicate's at-rest bounds (``rest_speed_m_s`` and
#: ``rest_angular_speed_rad_s`` × its window) over a whole window.
REST_EXIT_FRACTION = 0.25


class _AtRest:
    """Whether a released object has come to rest on the support during the settle: over the
    last ``rest_window_steps`` (sampled every call, i.e. every :data:`FALLEN_CHECK_STEPS`)
    its centre of mass stayed within :data:`REST_EXIT_FRACTION` of the predicate's distance
    bound of where the window began, its orientation within that fraction of the angle
    bound, and it touches the support. Under constant gravity and damping nothing else in
    the world moves (the arm has retreated and holds still), so the rest of the settle would
    leave it where it is; the predicate then observes it for its own window as always."""

    def __init__(self, world: World, obj: int, support: int, p: Perturbation):
        self.world, self.obj, self.support = world, obj, support
        duration = p.rest_window_steps * world.dt
        self.max_dist = REST_EXIT_FRACTION * p.rest_speed_m_s * duration
        self.max_angle = REST_EXIT_FRACTION * p.rest_angular_speed_rad_s * duration
        self.n = -(-p.rest_window_steps // FALLEN_CHECK_STEPS) + 1  # samples spanning a window
        self.poses: list[tuple] = []

    def __call__(self) -> bool:
        cid = self.world.cid
        self.poses.append(pb.getBasePositionAndOrientation(self.obj, physicsClientId=cid))
        if len(self.poses) < self.n:
            return False
        window = self.poses[-self.n:]
        p0, q0 = np.asarray(window[0][0]), np.asarray(window[0][1])
        for p, q in window[1:]:
            if np.linalg.norm(np.asarray(p) - p0) > self.max_dist:
                return False
            if 2.0 * np.arccos(min(1.0, abs(float(np.dot(q, q0))))) > self.max_angle:
                return False
        return bool(self.world.contacts(self.obj, self.support))


def _attach(world: World, body: int, link: int, obj: int, max_force: float) -> int:
    """Fixed constraint holding ``obj`` at its current pose relative to ``body``'s ``link``
    (−1: the base; both frames are PyBullet's centre-of-mass frames)."""
    if link >= 0:
        state = pb.getLinkState(body, link, computeForwardKinematics=1, physicsClientId=world.cid)
        frame = pose_matrix(state[0], state[1])
    else:
        frame = pose_matrix(*pb.getBasePositionAndOrientation(body, physicsClientId=world.cid))
    obj_pos, obj_quat = pb.getBasePositionAndOrientation(obj, physicsClientId=world.cid)
    rel = invert(frame) @ pose_matrix(obj_pos, obj_quat)
    pos, quat = matrix_pose(rel)
    cid = pb.createConstraint(body, link, obj, -1, pb.JOINT_FIXED, [0, 0, 0],
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


class _KeypointProbe:
    """Distance of the object's keypoint from a commanded keypoint frame, read from the
    base (centre-of-mass) pose PyBullet reports, without a pose conversion per call."""

    def __init__(self, world: World, obj: int, keypoint: np.ndarray):
        self.world, self.obj = world, obj
        info = pb.getDynamicsInfo(obj, -1, physicsClientId=world.cid)
        self.local = (invert(pose_matrix(info[3], info[4])) @ keypoint)[:3, 3]  # in the COM frame

    def error(self, xi: np.ndarray) -> float:
        pos, quat = pb.getBasePositionAndOrientation(self.obj, physicsClientId=self.world.cid)
        rot = np.reshape(pb.getMatrixFromQuaternion(quat), (3, 3))
        return float(np.linalg.norm(rot @ self.local + pos - self.world.to_world(xi)[:3, 3]))


def _end(row: dict, reason: str, trace: _Trace) -> dict:
    row["failure_reason"] = reason
    return {"row": row, "trace": trace.frames, "skt": trace.skt}
