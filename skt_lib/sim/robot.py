"""The Franka Panda of ``pybullet_data`` (``franka_panda/panda.urdf``): loading, inverse
kinematics and joint position control of its grasp target (the point between the
fingertips, link ``panda_grasptarget``). Its z axis is the approach direction.

Set-up IK (:meth:`Panda.joint_path`) uses :class:`skt_lib.sim.kinematics.Chain`, the arm's
kinematics read from the same URDF: damped least squares with the joint limits as hard
bounds, so a path that runs along a limit is tracked on it rather than clipped off it. A
path is solved from its last pose — the hang, where the hand is most constrained — from
several start configurations, and tracked backward pose by pose to the start.
"""

import functools
import os
from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

import numpy as np
import pybullet as pb
import pybullet_data

from skt_lib.geometry.se3 import matrix_pose, pose_matrix
from skt_lib.sim.kinematics import Chain, IKSettings
from skt_lib.sim.world import World

PANDA_URDF = os.path.join(pybullet_data.getDataPath(), "franka_panda", "panda.urdf")
ARM = tuple(range(7))
FINGERS = (9, 10)
GRASP_LINK = 11
FINGER_OPEN_M = 0.04
GRASP_LINK_NAME = "panda_grasptarget"
#: The first IK start: elbow up, hand forward.
REST_Q = (0.0, -0.4, 0.0, -2.2, 0.0, 1.8, 0.785)
#: Solving one pose from a start configuration far away / tracking from the previous pose.
GLOBAL_IK = IKSettings(max_iterations=100)
TRACK_IK = IKSettings(max_iterations=20, rest_gain=0.05)
#: Set-up checks a path at every this many poses first, then at every pose.
COARSE_STRIDE = 8

IKCheck = Literal["unreachable_hang", "tracking_tolerance", "joint_jump", "clearance"]


@dataclass(frozen=True)
class IKFailure:
    """Why :meth:`Panda.joint_path` found no joint path: the first check that failed on the
    start configuration that got furthest. ``index`` is the pose (0-based, of ``n_poses``,
    execution order; the last is the hang) where it failed; ``error_m``/``error_rad`` the grasp-target error there, ``jump_rad`` the
    largest joint change into it (0 when not computed)."""

    check: IKCheck
    index: int
    n_poses: int
    error_m: float = 0.0
    error_rad: float = 0.0
    jump_rad: float = 0.0

    def describe(self) -> str:
        return (f"{self.check} at pose {self.index}/{self.n_poses} (error {1000 * self.error_m:.1f} mm, "
                f"{self.error_rad:.3f} rad, jump {self.jump_rad:.3f} rad)")


_STAGE = {"unreachable_hang": 0, "tracking_tolerance": 1, "joint_jump": 1, "clearance": 2}


def rank(f: IKFailure) -> tuple[int, int]:
    """How far a failed start configuration got: tracked to the start but not clear, beats
    tracked part of the way (the fewer poses left the better), beats an unreachable hang."""
    return _STAGE[f.check], -f.index


@functools.lru_cache(maxsize=8)
def _start_seeds(n: int, lower: tuple, upper: tuple) -> tuple[np.ndarray, ...]:
    """:meth:`Panda.start_seeds`, drawn once per process (a trial tries it per grasp
    candidate: hundreds of times)."""
    rng = np.random.default_rng(0)
    seeds = (np.asarray(REST_Q, float),
             *(rng.uniform(np.array(lower), np.array(upper)) for _ in range(n - 1)))
    for s in seeds:
        s.flags.writeable = False
    return seeds


class Panda:
    """One Panda in ``world`` with its base at ``base_world`` (4×4, world frame).

    ``compiled``: set-up IK with the numba kernel (else the numpy reference);
    ``visual``: load the visual meshes too (for drawing only: they are four fifths of the
    load time, and nothing in the physics uses them)."""

    def __init__(self, world: World, base_world: np.ndarray, compiled: bool = True,
                 visual: bool = False):
        self.cid = world.cid
        pos, quat = matrix_pose(base_world)
        self.body = pb.loadURDF(PANDA_URDF, pos, quat, useFixedBase=True,
                                flags=0 if visual else pb.URDF_IGNORE_VISUAL_SHAPES,
                                physicsClientId=self.cid)
        info = [pb.getJointInfo(self.body, j, physicsClientId=self.cid) for j in ARM]
        self.lower = np.array([i[8] for i in info])
        self.upper = np.array([i[9] for i in info])
        self.max_force = [i[10] for i in info]
        self.max_velocity = np.array([i[11] for i in info])  # rad/s, the URDF's limits
        self.chain = Chain(PANDA_URDF, GRASP_LINK_NAME, base_world, compiled=compiled)
        self.mid = (self.lower + self.upper) / 2.0  # tracking drifts toward mid-range
        if not (np.array_equal(self.chain.lower, self.lower)
                and np.array_equal(self.chain.upper, self.upper)):
            raise RuntimeError(f"{PANDA_URDF}: the kinematic chain's limits differ from PyBullet's")
        self.n_links = pb.getNumJoints(self.body, physicsClientId=self.cid)
        self.reset(REST_Q, FINGER_OPEN_M)

    # -- state -------------------------------------------------------------
    def reset(self, q, finger: float) -> None:
        """Teleport the arm to joints ``q`` (7,) and the fingers to ``finger`` metres each,
        and hold them there (set-up only: never during a trial)."""
        for j, v in zip(ARM, q):
            pb.resetJointState(self.body, j, float(v), 0.0, physicsClientId=self.cid)
        for j in FINGERS:
            pb.resetJointState(self.body, j, finger, 0.0, physicsClientId=self.cid)
        self.command(q)
        self.command_fingers(finger)

    def q(self) -> np.ndarray:
        return np.array([s[0] for s in pb.getJointStates(self.body, ARM, physicsClientId=self.cid)])

    def grasp_world(self) -> np.ndarray:
        """World pose (4×4) of the grasp target."""
        s = pb.getLinkState(self.body, GRASP_LINK, computeForwardKinematics=1,
                            physicsClientId=self.cid)
        return pose_matrix(s[4], s[5])

    def link_poses(self) -> np.ndarray:
        """World poses ``(n_links + 1, 4, 4)`` of the base and every link frame (for logging)."""
        base = pb.getBasePositionAndOrientation(self.body, physicsClientId=self.cid)
        out = [pose_matrix(*base)]
        for s in pb.getLinkStates(self.body, list(range(self.n_links)), computeForwardKinematics=1,
                                  physicsClientId=self.cid):
            out.append(pose_matrix(s[4], s[5]))
        return np.stack(out)

    # -- kinematics and control --------------------------------------------
    def ik(self, target_world: np.ndarray) -> np.ndarray:
        """Joint positions (7,) inside the limits that put the grasp target at
        ``target_world``, searched from the current joint state. Does not move the arm."""
        return self.chain.solve(target_world, self.q(), settings=TRACK_IK)[0]

    def start_seeds(self, n: int) -> list[np.ndarray]:
        """IK start configurations: :data:`REST_Q`, then ``n − 1`` fixed pseudo-random ones
        inside the joint limits (the same list every time; read-only arrays)."""
        return list(_start_seeds(n, tuple(self.lower), tuple(self.upper)))

    def joint_path(self, targets: np.ndarray, tol_m: float, tol_rad: float,
                   max_jump_rad: float, restarts: int,
                   accept_start: Callable[[np.ndarray], bool] | None = None,
                   first_blocked: Callable[[np.ndarray], int] | None = None
                   ) -> np.ndarray | IKFailure:
        """Set-up (kinematic, before a trial): joint positions ``(M, 7)`` that put the grasp
        target on every pose of ``targets`` ((M, 4, 4) world poses, execution order) within
        ``tol_m``/``tol_rad``, each within ``max_jump_rad`` (every joint) of the previous one.

        The last pose (the hang) is solved from each of :meth:`start_seeds` in order; every
        earlier pose is solved from the solution of the pose after it. A tracked path whose
        first configuration ``accept_start(q (7,))`` rejects (e.g. a collision at the set-up
        pose) fails as ``clearance``, and so does one for which ``first_blocked(path)``
        returns a pose index ≥ 0 (e.g. the arm through the support). Returns the path of the
        first seed that passes, else the :class:`IKFailure` of the seed that got furthest.
        Leaves the arm at the path's start (at the last configuration tried on failure)."""
        targets = np.asarray(targets, float)
        n = len(targets)
        worst: IKFailure | None = None
        ends: list[np.ndarray] = []
        for seed in self.start_seeds(restarts):
            q_end, d, a = self.chain.solve(targets[-1], seed, settings=GLOBAL_IK)
            if d > tol_m or a > tol_rad:
                fail = IKFailure("unreachable_hang", n - 1, n, d, a)
            elif any(np.abs(q_end - e).max() < 1e-3 for e in ends):
                continue  # the same hang configuration as a seed tried before: the same path
            else:
                ends.append(q_end)
                fail, path = self._checked_path(targets, q_end, tol_m, tol_rad, max_jump_rad,
                                                accept_start, first_blocked)
                if fail is None:
                    self.reset(path[0], FINGER_OPEN_M)
                    return path
            if worst is None or rank(fail) > rank(worst):
                worst = fail
        assert worst is not None
        return worst

    def _checked_path(self, targets, q_end, tol_m, tol_rad, max_jump_rad, accept_start,
                      first_blocked):
        """Track from ``q_end`` and check, first every :data:`COARSE_STRIDE`-th pose (a cheap
        filter: most candidates fail on it), then every pose: ``(None, path (M, 7))`` or
        ``(IKFailure, None)``."""
        n = len(targets)
        for stride in (COARSE_STRIDE, 1):
            fail, path, index = self._track(targets, q_end, tol_m, tol_rad,
                                            stride * max_jump_rad, stride)
            if fail is None and accept_start is not None and not accept_start(path[0]):
                fail = IKFailure("clearance", 0, n)
            if fail is None and first_blocked is not None:
                k = first_blocked(path)
                if k >= 0:
                    fail = IKFailure("clearance", index[k], n)
            if fail is not None:
                return fail, None
        return None, path

    def _track(self, targets, q_end, tol_m, tol_rad, max_jump_rad, stride=1):
        """Track every ``stride``-th pose of ``targets`` (and the first) backward from
        ``q_end`` at the last: ``(None, path (K, 7), pose indices (K,))`` in execution order,
        or ``(IKFailure, None, None)`` at the first pose that fails."""
        n = len(targets)
        index = [*range(n - 1, 0, -stride), 0] if n > 1 else [0]
        path, fail = self.chain.track(np.asarray(targets)[index[1:]], q_end, self.mid, TRACK_IK,
                                      tol_m, tol_rad, max_jump_rad)
        if fail is not None:
            check, k, d, a, jump = fail
            return IKFailure(check, index[k + 1], n, d, a, jump), None, None
        return None, np.ascontiguousarray(path[::-1]), index[::-1]

    def pose_error(self, target_world: np.ndarray) -> tuple[float, float]:
        """(position error m, rotation error rad) of the grasp target against a target."""
        s = pb.getLinkState(self.body, GRASP_LINK, computeForwardKinematics=1,
                            physicsClientId=self.cid)
        rot = np.reshape(pb.getMatrixFromQuaternion(s[5]), (3, 3))
        cos = (np.sum(rot * target_world[:3, :3]) - 1.0) / 2.0  # trace(rot.T @ target)
        angle = float(np.arccos(np.clip(cos, -1.0, 1.0)))
        return float(np.linalg.norm(np.subtract(s[4], target_world[:3, 3]))), angle

    def command(self, q) -> None:
        pb.setJointMotorControlArray(self.body, ARM, pb.POSITION_CONTROL, targetPositions=list(q),
                                     forces=self.max_force, positionGains=[0.3] * 7,
                                     physicsClientId=self.cid)

    def command_fingers(self, width: float) -> None:
        pb.setJointMotorControlArray(self.body, FINGERS, pb.POSITION_CONTROL,
                                     targetPositions=[width, width], forces=[20.0, 20.0],
                                     physicsClientId=self.cid)

    def set_collision_with(self, body: int, enable: bool) -> None:
        """Enable or disable collisions between every robot link and ``body``'s base."""
        for link in range(-1, self.n_links):
            pb.setCollisionFilterPair(self.body, body, link, -1, int(enable), physicsClientId=self.cid)
