"""The Franka Panda of ``pybullet_data`` (``franka_panda/panda.urdf``): loading, inverse
kinematics and joint position control of its grasp target (the point between the
fingertips, link ``panda_grasptarget``). Its z axis is the approach direction.
"""

import os

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
#: The first IK start: elbow up, hand forward.
REST_Q = (0.0, -0.4, 0.0, -2.2, 0.0, 1.8, 0.785)


class Panda:
    """One Panda in ``world`` with its base at ``base_world`` (4×4, world frame)."""

    def __init__(self, world: World, base_world: np.ndarray, ik_iterations: int = 100):
        self.cid = world.cid
        pos, quat = matrix_pose(base_world)
        self.body = pb.loadURDF(PANDA_URDF, pos, quat, useFixedBase=True, physicsClientId=self.cid)
        info = [pb.getJointInfo(self.body, j, physicsClientId=self.cid) for j in ARM]
        self.lower = [i[8] for i in info]
        self.upper = [i[9] for i in info]
        self.max_force = [i[10] for i in info]
        self.ik_iterations = ik_iterations
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
        the current joint state (PyBullet's damped least squares), clipped to the limits."""
        pos, quat = matrix_pose(target_world)
        q = pb.calculateInverseKinematics(self.body, GRASP_LINK, pos, quat,
                                          maxNumIterations=self.ik_iterations,
                                          residualThreshold=1e-5, physicsClientId=self.cid)
        return np.clip(np.asarray(q[:7]), self.lower, self.upper)

    def _reach(self, target_world: np.ndarray, rounds: int) -> np.ndarray:
        """Teleport-and-refine IK from the current joints; leaves the arm at the result."""
        q = self.q()
        for _ in range(rounds):
            q = self.ik(target_world)
            self.reset(q, FINGER_OPEN_M)
            if np.linalg.norm(self.grasp_world()[:3, 3] - target_world[:3, 3]) < 1e-4:
                break
        return q

    def start_seeds(self, n: int) -> list[np.ndarray]:
        """IK start configurations: :data:`REST_Q`, then ``n − 1`` fixed pseudo-random ones
        inside the joint limits (the same list every time)."""
        rng = np.random.default_rng(0)
        return [np.asarray(REST_Q)] + [rng.uniform(self.lower, self.upper) for _ in range(n - 1)]

    def joint_path(self, targets: list[np.ndarray], tol_m: float, tol_rad: float,
                   max_jump_rad: float, restarts: int) -> np.ndarray | None:
        """Set-up (kinematic, before a trial): joint positions ``(M, 7)`` that put the grasp
        target on every pose of ``targets`` within ``tol_m``/``tol_rad``, each within
        ``max_jump_rad`` of the previous one; tried from each of :meth:`start_seeds` in
        order. ``None`` when no seed gives such a path. Leaves the arm at the path's start."""
        for seed in self.start_seeds(restarts):
            self.reset(seed, FINGER_OPEN_M)
            path = [self._reach(targets[0], 20)]
            ok = self._close(targets[0], tol_m, tol_rad)
            for target in targets[1:] if ok else ():
                q = self._reach(target, 3)
                if not self._close(target, tol_m, tol_rad) or np.abs(q - path[-1]).max() > max_jump_rad:
                    ok = False
                    break
                path.append(q)
            if ok:
                self.reset(path[0], FINGER_OPEN_M)
                return np.stack(path)
        return None

    def _close(self, target: np.ndarray, tol_m: float, tol_rad: float) -> bool:
        d, a = self.pose_error(target)
        return d <= tol_m and a <= tol_rad

    def pose_error(self, target_world: np.ndarray) -> tuple[float, float]:
        """(position error m, rotation error rad) of the grasp target against a target."""
        t = self.grasp_world()
        r = t[:3, :3].T @ target_world[:3, :3]
        angle = float(np.arccos(np.clip((np.trace(r) - 1.0) / 2.0, -1.0, 1.0)))
        return float(np.linalg.norm(t[:3, 3] - target_world[:3, 3])), angle

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
