"""The Franka Panda of ``pybullet_data`` (``franka_panda/panda.urdf``): loading, inverse
kinematics and joint position control of its grasp target (the point between the
fingertips, link ``panda_grasptarget``). Its z axis is the approach direction.

Set-up IK (:meth:`Panda.joint_path`) is PyBullet's null-space IK — limits, ranges and rest
poses given for all 9 DoF (7 arm joints + 2 fingers; with fewer entries PyBullet silently
falls back to plain IK) and the rest pose set to the previous solution, so that each solve
stays in the basin of the one before — followed by a few rounds of plain damped least
squares refinement (null-space IK alone leaves millimetres of error). Every result is
clipped to the joint limits and checked by forward kinematics.
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
from skt_lib.sim.world import World

PANDA_URDF = os.path.join(pybullet_data.getDataPath(), "franka_panda", "panda.urdf")
ARM = tuple(range(7))
FINGERS = (9, 10)
GRASP_LINK = 11
FINGER_OPEN_M = 0.04
#: Finger joint limits (prismatic, metres each), as in the URDF.
FINGER_LIMITS_M = (0.0, 0.04)
#: The first IK start: elbow up, hand forward.
REST_Q = (0.0, -0.4, 0.0, -2.2, 0.0, 1.8, 0.785)

IKCheck = Literal["unreachable_start", "tracking_tolerance", "joint_jump", "clearance"]


@dataclass(frozen=True)
class IKFailure:
    """Why :meth:`Panda.joint_path` found no joint path: the first check that failed on the
    start configuration that got furthest. ``index`` is the pose (0-based, of ``n_poses``)
    where it failed; ``error_m``/``error_rad`` the grasp-target error there, ``jump_rad`` the
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


def _pos_quat(t: np.ndarray) -> tuple[tuple[float, ...], tuple[float, ...]]:
    """Position and xyzw quaternion of a 4×4 pose (memoised: each set-up target is handed to
    PyBullet's IK several times)."""
    return _pos_quat_of_bytes(np.ascontiguousarray(t, dtype=np.float64).tobytes())


@functools.lru_cache(maxsize=64)
def _pos_quat_of_bytes(key: bytes) -> tuple[tuple[float, ...], tuple[float, ...]]:
    pos, quat = matrix_pose(np.frombuffer(key, dtype=np.float64).reshape(4, 4))
    return tuple(map(float, pos)), tuple(map(float, quat))


def _rank(f: IKFailure) -> tuple[int, bool]:
    """How far a failed seed got (a start that was reached but not clear beats none)."""
    return f.index, f.check != "unreachable_start"


class Panda:
    """One Panda in ``world`` with its base at ``base_world`` (4×4, world frame)."""

    def __init__(self, world: World, base_world: np.ndarray, ns_iterations: int = 20,
                 refine_rounds: int = 3):
        self.cid = world.cid
        pos, quat = matrix_pose(base_world)
        self.body = pb.loadURDF(PANDA_URDF, pos, quat, useFixedBase=True, physicsClientId=self.cid)
        info = [pb.getJointInfo(self.body, j, physicsClientId=self.cid) for j in ARM]
        self.lower = np.array([i[8] for i in info])
        self.upper = np.array([i[9] for i in info])
        self.max_force = [i[10] for i in info]
        # one entry per DoF (movable joint) of the URDF: 7 arm joints, then the 2 fingers
        n_dof = sum(pb.getJointInfo(self.body, j, physicsClientId=self.cid)[2] != pb.JOINT_FIXED
                    for j in range(pb.getNumJoints(self.body, physicsClientId=self.cid)))
        if n_dof != 9:
            raise RuntimeError(f"{PANDA_URDF}: expected 9 degrees of freedom, found {n_dof}")
        self._ll = [*self.lower, *(FINGER_LIMITS_M[0],) * 2]
        self._ul = [*self.upper, *(FINGER_LIMITS_M[1],) * 2]
        self._jr = [u - lo for u, lo in zip(self._ul, self._ll)]
        self.ns_iterations, self.refine_rounds = ns_iterations, refine_rounds
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
        """Joint positions (7,) that put the grasp target at ``target_world``, searched from
        the current joint state (PyBullet's plain damped least squares), clipped to the limits.
        Does not move the arm."""
        pos, quat = _pos_quat(target_world)
        q = pb.calculateInverseKinematics(self.body, GRASP_LINK, pos, quat, maxNumIterations=100,
                                          residualThreshold=1e-5, physicsClientId=self.cid)
        return np.clip(np.asarray(q[:7]), self.lower, self.upper)

    def ik_nullspace(self, target_world: np.ndarray, rest_q) -> np.ndarray:
        """Null-space IK (7,) from the current joint state, pulled toward ``rest_q`` (7,),
        within the joint limits (9-entry arrays: arm + fingers). Does not move the arm."""
        pos, quat = _pos_quat(target_world)
        q = pb.calculateInverseKinematics(
            self.body, GRASP_LINK, pos, quat, lowerLimits=self._ll, upperLimits=self._ul,
            jointRanges=self._jr, restPoses=[*map(float, rest_q), FINGER_OPEN_M, FINGER_OPEN_M],
            maxNumIterations=self.ns_iterations, residualThreshold=1e-6, physicsClientId=self.cid)
        return np.clip(np.asarray(q[:7]), self.lower, self.upper)

    def solve(self, target_world: np.ndarray, rest_q, tol_m: float = 1e-4,
              tol_rad: float = 1e-3) -> np.ndarray:
        """Null-space IK toward ``rest_q``, then up to ``refine_rounds`` rounds of plain IK
        until the grasp target is within ``tol_m``/``tol_rad`` of ``target_world``. Leaves
        the arm (teleported) at the result, which it returns (7,), inside the limits."""
        q = self.ik_nullspace(target_world, rest_q)
        self.reset(q, FINGER_OPEN_M)
        for _ in range(self.refine_rounds):
            d, a = self.pose_error(target_world)
            if d <= tol_m and a <= tol_rad:
                break
            q = self.ik(target_world)
            self.reset(q, FINGER_OPEN_M)
        return q

    def start_seeds(self, n: int) -> list[np.ndarray]:
        """IK start configurations: :data:`REST_Q`, then ``n − 1`` fixed pseudo-random ones
        inside the joint limits (the same list every time)."""
        rng = np.random.default_rng(0)
        return [np.asarray(REST_Q)] + [rng.uniform(self.lower, self.upper) for _ in range(n - 1)]

    def joint_path(self, targets: list[np.ndarray], tol_m: float, tol_rad: float,
                   max_jump_rad: float, restarts: int,
                   accept_start: Callable[[np.ndarray], bool] | None = None,
                   first_blocked: Callable[[np.ndarray], int] | None = None) -> np.ndarray | IKFailure:
        """Set-up (kinematic, before a trial): joint positions ``(M, 7)`` that put the grasp
        target on every pose of ``targets`` (M world poses, 4×4) within ``tol_m``/``tol_rad``,
        each within ``max_jump_rad`` (every joint) of the previous one.

        The first pose is solved from each of :meth:`start_seeds` in order (rest pose = the
        seed); every later pose is solved from, and pulled toward, the previous solution.
        A start configuration that ``accept_start(q (7,))`` rejects (e.g. a collision at the
        set-up pose) fails as ``clearance``, and so does a tracked path ``(M, 7)`` for which
        ``first_blocked(path)`` returns a pose index ≥ 0 (e.g. the arm through the support).
        Returns the path of the first seed that tracks all of ``targets``, else the
        :class:`IKFailure` of the seed that got furthest. Leaves the arm at the path's start
        (at the last configuration tried on failure)."""
        n = len(targets)
        worst: IKFailure | None = None
        starts: list[np.ndarray] = []
        for seed in self.start_seeds(restarts):
            self.reset(seed, FINGER_OPEN_M)
            q0 = self.solve(targets[0], seed)
            d, a = self.pose_error(targets[0])
            if d > tol_m or a > tol_rad:
                fail = IKFailure("unreachable_start", 0, n, d, a)
            elif any(np.abs(q0 - s).max() < 1e-3 for s in starts):
                continue  # the same start as a seed tried before: the same path
            elif accept_start is not None and not accept_start(q0):
                starts.append(q0)
                fail = IKFailure("clearance", 0, n, d, a)
            else:
                starts.append(q0)
                fail, path = self._track(targets, q0, tol_m, tol_rad, max_jump_rad)
                if fail is None and first_blocked is not None:
                    k = first_blocked(path)
                    if k >= 0:
                        fail = IKFailure("clearance", k, n)
                if fail is None:
                    self.reset(path[0], FINGER_OPEN_M)
                    return path
            if worst is None or _rank(fail) > _rank(worst):
                worst = fail
        assert worst is not None
        return worst

    def _track(self, targets, q0, tol_m, tol_rad, max_jump_rad):
        path = [q0]
        for k, target in enumerate(targets[1:], start=1):
            q = self.solve(target, path[-1])
            d, a = self.pose_error(target)
            jump = float(np.abs(q - path[-1]).max())
            if d > tol_m or a > tol_rad:
                return IKFailure("tracking_tolerance", k, len(targets), d, a, jump), None
            if jump > max_jump_rad:
                return IKFailure("joint_jump", k, len(targets), d, a, jump), None
            path.append(q)
        return None, np.stack(path)

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
