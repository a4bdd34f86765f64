"""A PyBullet world in DIRECT mode, stepped deterministically (no sleeps, no wall clock).

The supporting item sits at one constant world pose, :data:`SUPPORT_POSE_WORLD`: the wall
faces the robot (at the world origin), so support +x (out of the wall) is world −x. Every
pose handed in or out of :class:`World` methods named ``*_support`` is in the support frame.
"""

import numpy as np
import pybullet as pb

from skt_lib.geometry.se3 import invert, matrix_pose, pose_matrix

#: World pose of the support frame: mounting point 0.75 m in front of the robot base,
#: 0.95 m above the floor, rotated 180° about z so that support +x points at the robot.
SUPPORT_POSE_WORLD = pose_matrix([0.75, 0.0, 0.95], [0.0, 0.0, 1.0, 0.0])
WALL_HALF_EXTENTS = (0.02, 0.6, 0.6)


class World:
    """Context manager owning one PyBullet client; pass ``world.cid`` everywhere."""

    def __init__(self, dt: float, solver_iterations: int, with_floor: bool = True):
        self.dt = dt
        self.cid = pb.connect(pb.DIRECT)
        pb.resetSimulation(physicsClientId=self.cid)
        pb.setPhysicsEngineParameter(fixedTimeStep=dt, numSolverIterations=solver_iterations,
                                     deterministicOverlappingPairs=1, physicsClientId=self.cid)
        self.floor = None
        self._inertial: dict[int, np.ndarray] = {}  # body -> link-frame pose of its COM frame
        self._inertial_pq: dict[int, tuple] = {}  # the same as (position, xyzw quaternion)
        self._support_pq = tuple(map(tuple, matrix_pose(SUPPORT_POSE_WORLD)))
        if with_floor:
            shape = pb.createCollisionShape(pb.GEOM_PLANE, physicsClientId=self.cid)
            self.floor = pb.createMultiBody(0, shape, physicsClientId=self.cid)
        self.set_gravity_support((0.0, 0.0, -9.81))

    def __enter__(self) -> "World":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        if self.cid is not None and pb.isConnected(self.cid):
            pb.disconnect(self.cid)
        self.cid = None

    # -- frames ------------------------------------------------------------
    @staticmethod
    def to_world(t_support: np.ndarray) -> np.ndarray:
        return SUPPORT_POSE_WORLD @ t_support

    @staticmethod
    def to_support(t_world: np.ndarray) -> np.ndarray:
        return invert(SUPPORT_POSE_WORLD) @ t_world

    # -- bodies ------------------------------------------------------------
    def add_wall(self) -> int:
        """A static wall whose surface is the support frame's x = 0 plane."""
        h = WALL_HALF_EXTENTS
        shape = pb.createCollisionShape(pb.GEOM_BOX, halfExtents=h, physicsClientId=self.cid)
        pos, quat = matrix_pose(self.to_world(pose_matrix([-h[0], 0, 0], [0, 0, 0, 1])))
        return pb.createMultiBody(0, shape, basePosition=pos, baseOrientation=quat,
                                  physicsClientId=self.cid)

    def load(self, urdf: str, t_support: np.ndarray, fixed: bool, friction: float,
             linear_damping: float | None = None, angular_damping: float | None = None) -> int:
        """Load ``urdf`` with its link frame at ``t_support`` (support frame).

        ``linear_damping`` / ``angular_damping``: PyBullet's multibody damping rates, 1/s
        (force −k·m·v, torque −k·I·ω; ``None`` keeps PyBullet's default 0.04). They stand in
        for the air drag and contact losses that PyBullet's rolling contacts lack, so that a
        hung object stops swinging."""
        pos, quat = matrix_pose(self.to_world(t_support))
        body = pb.loadURDF(urdf, pos, quat, useFixedBase=fixed, physicsClientId=self.cid)
        pb.changeDynamics(body, -1, lateralFriction=friction, spinningFriction=0.001,
                          rollingFriction=0.0001, physicsClientId=self.cid)
        if linear_damping is not None:
            pb.changeDynamics(body, -1, linearDamping=linear_damping, physicsClientId=self.cid)
        if angular_damping is not None:
            pb.changeDynamics(body, -1, angularDamping=angular_damping, physicsClientId=self.cid)
        info = pb.getDynamicsInfo(body, -1, physicsClientId=self.cid)
        self._inertial[body] = pose_matrix(info[3], info[4])
        self._inertial_pq[body] = (info[3], info[4])
        return body

    def pose_support(self, body: int) -> np.ndarray:
        """Pose of the body's link (URDF) frame in the support frame.

        PyBullet reports the base's centre-of-mass frame; this converts it."""
        pos, quat = pb.getBasePositionAndOrientation(body, physicsClientId=self.cid)
        return self.to_support(pose_matrix(pos, quat) @ invert(self._inertial[body]))

    def set_pose_support(self, body: int, t_support: np.ndarray) -> None:
        """Place the body's link frame at ``t_support`` and zero its velocity."""
        pos, quat = matrix_pose(self.to_world(t_support) @ self._inertial[body])
        pb.resetBasePositionAndOrientation(body, pos, quat, physicsClientId=self.cid)
        pb.resetBaseVelocity(body, [0, 0, 0], [0, 0, 0], physicsClientId=self.cid)

    def set_pose_support_pq(self, body: int, position, quat) -> None:
        """Fast path of :meth:`set_pose_support` for planners: position (3,) and xyzw
        quaternion of the link frame in the support frame; velocities untouched."""
        pos, orn = pb.multiplyTransforms(*self._support_pq, position, quat)
        pos, orn = pb.multiplyTransforms(pos, orn, *self._inertial_pq[body])
        pb.resetBasePositionAndOrientation(body, pos, orn, physicsClientId=self.cid)

    def com_support(self, body: int) -> np.ndarray:
        """Centre of mass of ``body`` in the support frame."""
        pos, _ = pb.getBasePositionAndOrientation(body, physicsClientId=self.cid)
        return (invert(SUPPORT_POSE_WORLD) @ np.append(pos, 1.0))[:3]

    def point_to_support(self, p_world) -> np.ndarray:
        return (invert(SUPPORT_POSE_WORLD) @ np.append(np.asarray(p_world, float), 1.0))[:3]

    # -- physics -----------------------------------------------------------
    def set_gravity_support(self, g_support) -> None:
        """Gravity given in the support frame (m/s²)."""
        g = SUPPORT_POSE_WORLD[:3, :3] @ np.asarray(g_support, dtype=np.float64)
        pb.setGravity(*g, physicsClientId=self.cid)

    def step(self, n: int) -> None:
        for _ in range(n):
            pb.stepSimulation(physicsClientId=self.cid)

    def min_distance(self, a: int, b: int, max_distance: float = 0.05) -> float:
        pts = pb.getClosestPoints(a, b, max_distance, physicsClientId=self.cid)
        return min((p[8] for p in pts), default=max_distance)

    def contacts(self, a: int, b: int) -> list:
        return list(pb.getContactPoints(a, b, physicsClientId=self.cid))
