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


#: Obstacles are queried only where the probe may come within the clearance + this of them
#: (m): PyBullet's distances can fall short of the geometric ones by its collision margin
#: (1 mm on convex meshes, measured), so skipping a query beyond this never changes a verdict.
GATE_SLACK_M = 0.005


def obstacle_boxes(world: World, bodies: list[int]) -> list[tuple[np.ndarray, np.ndarray]]:
    """``(lo, hi)`` in the support frame of each body's PyBullet AABB (every link; margins
    and PyBullet's own padding included): a box that holds everything a query can meet."""
    to_support = world.to_support(np.eye(4))
    out = []
    for body in bodies:
        boxes = [pb.getAABB(body, j, physicsClientId=world.cid)
                 for j in range(-1, pb.getNumJoints(body, physicsClientId=world.cid))]
        lo, hi = np.min([b[0] for b in boxes], axis=0), np.max([b[1] for b in boxes], axis=0)
        corners = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
        moved = corners @ to_support[:3, :3].T + to_support[:3, 3]
        out.append((moved.min(0), moved.max(0)))
    return out


def make_probe_collision_fn(world: World, probe: int, obstacles: list[int], clearance: float,
                            tolerance: float, hang: np.ndarray | None = None,
                            others_from_m: float = 0.0, wall: np.ndarray | None = None,
                            wall_from_m: float = 0.0, probe_hull: np.ndarray | None = None):
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
    object's own: some cross the wall within millimetres of it and settle off it).

    ``probe_hull`` (:func:`wall_points` of the probe's own collision parts): an obstacle is
    then queried only where the probe can reach its box (:func:`obstacle_boxes`) within
    ``clearance`` + :data:`GATE_SLACK_M` — its bounding sphere, then its hull's least x
    (the wall and a support's tip lie behind the probe for much of a path). A skipped query
    is one that would have found nothing: the verdicts are the same, bit for bit
    (``tests/planning/test_probe.py``)."""
    cid = world.cid
    support_pq = tuple(map(tuple, matrix_pose(SUPPORT_POSE_WORLD)))
    near_sq = others_from_m ** 2 if hang is not None else -1.0
    wall_near_sq = wall_from_m ** 2 if hang is not None else -1.0
    hx, hy, hz = (0.0, 0.0, 0.0) if hang is None else map(float, hang)
    reach = clearance + GATE_SLACK_M
    if probe_hull is not None:
        radius = float(np.linalg.norm(probe_hull, axis=1).max())
        gates = [(o, *map(float, lo - reach), *map(float, hi + reach))
                 for o, (lo, hi) in zip(obstacles, obstacle_boxes(world, obstacles))]
    else:
        radius, gates = np.inf, [(o,) + (-np.inf,) * 3 + (np.inf,) * 3 for o in obstacles]

    def collides(position, quat) -> bool:
        """``position`` (3,) and xyzw ``quat`` of the keypoint frame, support frame."""
        px, py, pz = float(position[0]), float(position[1]), float(position[2])
        d2 = (px - hx) ** 2 + (py - hy) ** 2 + (pz - hz) ** 2
        x_axis = None
        if wall is not None and d2 >= wall_near_sq:
            x_axis = pb.getMatrixFromQuaternion(quat)[:3]  # the frame's rotation, first row
            if float((wall @ x_axis).min()) + px < 0.0:
                return True
        only_reference = {"linkIndexA": 0} if d2 < near_sq else {}
        placed = False
        least_x = None
        for o, lx, ly, lz, ux, uy, uz in gates:
            gx = lx - px if px < lx else (px - ux if px > ux else 0.0)
            gy = ly - py if py < ly else (py - uy if py > uy else 0.0)
            gz = lz - pz if pz < lz else (pz - uz if pz > uz else 0.0)
            if gx * gx + gy * gy + gz * gz > radius * radius:
                continue  # the bounding sphere cannot reach the box
            if probe_hull is not None:
                if least_x is None:
                    if x_axis is None:
                        x_axis = pb.getMatrixFromQuaternion(quat)[:3]
                    least_x = float((probe_hull @ x_axis).min()) + px
                if least_x > ux:
                    continue  # the whole probe lies in front of the box
            if not placed:
                pos, orn = pb.multiplyTransforms(*support_pq, position, quat)
                pb.resetBasePositionAndOrientation(probe, pos, orn, physicsClientId=cid)
                placed = True
            for c in pb.getClosestPoints(probe, o, clearance, physicsClientId=cid, **only_reference):
                if c[3] == 0 or c[8] < -tolerance:
                    return True
        return False

    return collides
