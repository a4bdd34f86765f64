"""The planner's probe: several objects held at one keypoint frame, as one PyBullet body.

An SKT is object-agnostic only if every object that follows it clears the support. The
probe puts each given object (the reference and the training objects) with its keypoint
frame at the probe's frame — a multibody whose links are the objects' compound collision
shapes (the same convex parts as their URDFs) — so one ``getClosestPoints`` query checks
them all (about 30 µs here, against about 300 µs for twenty separate bodies).

The wall is a plane (x = 0, support frame), so how far an object reaches toward it is the
least x of its mesh's vertices — the least of a linear function over the mesh, found exactly
at its convex hull's vertices (:func:`wall_points`): a few hundred dot products per pose
instead of a PyBullet query, so the training objects can be kept off the wall everywhere.
"""

from dataclasses import dataclass

import numpy as np
import pybullet as pb
from scipy.spatial import ConvexHull

from skt_lib.geometry.se3 import invert, matrix_pose
from skt_lib.sim.world import SUPPORT_POSE_WORLD, World


@dataclass(frozen=True)
class ProbeObject:
    collision_obj: str  # multi-object OBJ, one convex part per object (``collision.obj``)
    keypoint: tuple[float, ...]  # 16 floats: keypoint frame in the object frame (row-major)


def add_probe(world: World, objects: list[ProbeObject]) -> int:
    """A massless multibody in ``world`` whose frame is the shared keypoint frame."""
    if not objects:
        raise ValueError("objects: the probe needs at least one object")
    shapes, poses = [], []
    for o in objects:
        shapes.append(pb.createCollisionShape(pb.GEOM_MESH, fileName=o.collision_obj,
                                              physicsClientId=world.cid))
        poses.append(matrix_pose(invert(np.asarray(o.keypoint, float).reshape(4, 4))))
    n = len(shapes)
    return pb.createMultiBody(
        0, -1, -1, [0, 0, 0], [0, 0, 0, 1],
        linkMasses=[0] * n, linkCollisionShapeIndices=shapes, linkVisualShapeIndices=[-1] * n,
        linkPositions=[p.tolist() for p, _ in poses], linkOrientations=[q.tolist() for _, q in poses],
        linkInertialFramePositions=[[0, 0, 0]] * n, linkInertialFrameOrientations=[[0, 0, 0, 1]] * n,
        linkParentIndices=[0] * n, linkJointTypes=[pb.JOINT_FIXED] * n, linkJointAxis=[[0, 0, 1]] * n,
        physicsClientId=world.cid)


def wall_points(meshes_and_keypoints) -> np.ndarray:
    """``(K, 3)``: the convex hull vertices of the given ``(mesh, keypoint (4, 4))`` pairs'
    vertices in their keypoint frames, together: the least x (support frame) of any of those
    objects held at a keypoint frame is the least x of these points there."""
    points = np.vstack([np.c_[m.vertices, np.ones(len(m.vertices))] @ invert(k).T
                        for m, k in meshes_and_keypoints])[:, :3]
    return points[ConvexHull(points).vertices]


def make_probe_collision_fn(world: World, probe: int, obstacles: list[int], clearance: float,
                            tolerance: float, hang: np.ndarray | None = None,
                            others_from_m: float = 0.0, wall: np.ndarray | None = None,
                            wall_from_m: float = 0.0):
    """``fn(position, quat) -> True`` when, with the probe's keypoint frame there (support
    frame), its first object (the reference) comes within ``clearance`` of any of
    ``obstacles``, or any other object penetrates one deeper than ``tolerance`` (PyBullet
    signed distances, m). Shallow penetrations of objects that did not shape the hang are
    resolved by contact in simulation (measured: test-object sweeps within 3 mm all hung).

    With ``hang`` (the hanging keypoint position, support frame), the other objects are
    checked only where the keypoint lies at least ``others_from_m`` from it: near the hang
    each object settles its own way (a mug's body reaches the wall plate where the ring hangs
    free), so there the reference alone decides.

    ``wall`` (:func:`wall_points` of objects outside the probe, e.g. the training objects):
    the pose also collides where any of them crosses the wall plane, checked where the
    keypoint lies at least ``wall_from_m`` from ``hang`` (the reference's hang is not each
    object's own: some cross the wall within millimetres of it and settle off it)."""
    cid = world.cid
    support_pq = tuple(map(tuple, matrix_pose(SUPPORT_POSE_WORLD)))
    near_sq = others_from_m ** 2 if hang is not None else -1.0
    wall_near_sq = wall_from_m ** 2 if hang is not None else -1.0
    hang = np.zeros(3) if hang is None else np.asarray(hang, float)

    def collides(position, quat) -> bool:
        """``position`` (3,) and xyzw ``quat`` of the keypoint frame, support frame."""
        pos, orn = pb.multiplyTransforms(*support_pq, position, quat)
        pb.resetBasePositionAndOrientation(probe, pos, orn, physicsClientId=cid)
        d = np.subtract(position, hang)
        d2 = float(d @ d)
        if wall is not None and d2 >= wall_near_sq:
            x_axis = pb.getMatrixFromQuaternion(quat)[:3]  # the frame's rotation, first row
            if float((wall @ x_axis).min()) + position[0] < 0.0:
                return True
        only_reference = {"linkIndexA": 0} if d2 < near_sq else {}
        for o in obstacles:
            for c in pb.getClosestPoints(probe, o, clearance, physicsClientId=cid, **only_reference):
                if c[3] == 0 or c[8] < -tolerance:
                    return True
        return False

    return collides
