"""Forward simulation of hangs (paper Fig. 3b): where an object touches what it hangs on.

Two kinds of runs share one routine, :func:`simulate_hangs`:

- ``object_on_rod``: an object released around a horizontal rod (radius
  ``rod_radius_m``, from the wall along support +x) → its object-frame contact point;
- ``reference_on_support``: the reference object released around a support's hanging arm
  → the support-frame contact point and a collision-free, stable hanging pose (the goal
  of the planner).

Each run makes ``n_drops`` releases from random collision-free poses threaded on the arm;
every release is dropped, perturbed and judged by the predicate of
:mod:`skt_lib.sim.hanging`. Of the successful hangs the most consistent one (the medoid
of the contact points) is kept; its pose is nudged to ``goal_clearance_m`` clearance and
checked to survive the perturbation again from rest.
"""

from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pybullet as pb

from skt_lib.config import ContactSimParams
from skt_lib.geometry.se3 import matrix_pose, pose_matrix, random_rotation_small
from skt_lib.seeding import item_rng
from skt_lib.sim.hanging import G, HangCheck, Perturbation, check_hang, perturb
from skt_lib.sim.world import SUPPORT_POSE_WORLD, World

ROD_LENGTH_M = 0.25
ROD_CAP_RADIUS_M = 0.05
ROD_CAP_THICKNESS_M = 0.004
#: The test rod as a hanging arm (support frame, wall → tip) and the site objects are released at.
ROD_ARM = ((0.0, 0.0, 0.0), (ROD_LENGTH_M, 0.0, 0.0))
ROD_SITE = (0.13, 0.0, 0.0)
_PARK = pose_matrix([0.5, 0.0, 2.0], [0, 0, 0, 1])  # out of the way while placing


@dataclass(frozen=True)
class HangTask:
    """One run. ``support_urdf`` empty means the horizontal test rod."""

    item_id: str
    kind: str  # "object_on_rod" | "reference_on_support"
    object_id: str
    object_urdf: str
    aperture_clearance_m: float
    support_id: str
    support_urdf: str
    arm: tuple[tuple[float, float, float], ...]  # arm centreline (wall → tip), support frame
    hang_point: tuple[float, float, float]  # releases are centred here, on the arm
    arm_radius_m: float  # arm section radius
    seed: int
    params: ContactSimParams


def perturbation(p: ContactSimParams) -> Perturbation:
    q = p.perturb
    return Perturbation(q.accel_m_s2, q.steps_per_direction, q.settle_steps, q.rest_speed_m_s,
                        q.rest_angular_speed_rad_s, q.rest_window_steps)


def add_rod(world: World, radius: float, friction: float) -> int:
    """A static horizontal rod from the wall (x = 0) to x = ROD_LENGTH_M along support +x,
    capped at its end by a disc of radius :data:`ROD_CAP_RADIUS_M` (like a peg's end stop:
    without it the perturbation's outward tilt slides every object off a straight rod)."""
    shape = pb.createCollisionShapeArray(
        [pb.GEOM_CYLINDER, pb.GEOM_CYLINDER], radii=[radius, ROD_CAP_RADIUS_M],
        lengths=[ROD_LENGTH_M, ROD_CAP_THICKNESS_M],
        collisionFramePositions=[[0.0, 0.0, 0.0], [0.0, 0.0, ROD_LENGTH_M / 2]],
        physicsClientId=world.cid)
    t = world.to_world(pose_matrix([ROD_LENGTH_M / 2, 0, 0], [0, np.sin(np.pi / 4), 0, np.cos(np.pi / 4)]))
    pos, quat = matrix_pose(t)
    body = pb.createMultiBody(0, shape, basePosition=pos, baseOrientation=quat,
                              physicsClientId=world.cid)
    pb.changeDynamics(body, -1, lateralFriction=friction, physicsClientId=world.cid)
    return body


def arm_site(arm: np.ndarray, hang_point: np.ndarray, offset: float) -> tuple[np.ndarray, np.ndarray]:
    """Point and unit tangent on the polyline ``arm (M, 3)`` at path distance ``offset`` from
    its point nearest ``hang_point`` (clipped to the arm's ends)."""
    seg = np.diff(arm, axis=0)
    length = np.linalg.norm(seg, axis=1)
    keep = length > 1e-12
    arm, seg, length = np.vstack([arm[:1], arm[1:][keep]]), seg[keep], length[keep]
    s = np.concatenate([[0.0], np.cumsum(length)])
    # nearest point on the polyline to hang_point
    u = np.clip(((hang_point - arm[:-1]) * seg).sum(1) / length**2, 0.0, 1.0)
    near = arm[:-1] + u[:, None] * seg
    k = int(np.argmin(np.linalg.norm(near - hang_point, axis=1)))
    target = float(np.clip(s[k] + u[k] * length[k] + offset, 0.0, s[-1]))
    j = int(np.clip(np.searchsorted(s, target, side="right") - 1, 0, len(seg) - 1))
    tangent = seg[j] / length[j]
    return arm[j] + tangent * (target - s[j]), tangent


def release_pose(rng: np.random.Generator, task: HangTask, attempt: int = 0) -> np.ndarray:
    """Object link pose (support frame) with the arm through the aperture, just under its top.

    The ``attempt``-th draw (0-based, of ``max_init_tries``) puts the site on the arm within
    ``slide_noise_m × attempt / (max_init_tries − 1)`` (path length) of the hang point: the
    first draw of a drop releases at the hang point itself, and the site moves away along
    the arm only as far as it takes to find a clear release (where the aperture does not fit
    at the hang point). Released anywhere along a straight peg, the reference stays where it
    was dropped, so a site drawn at random made the contact label random along the arm
    (docs/pipeline.md: a median 8 mm between drop seeds on the easy validation supports).
    At the site the aperture axis (object +x) lies along the arm and object +z is
    perpendicular to it in the vertical plane; then a random roll about the axis and a random
    small tilt."""
    p = task.params
    reach = attempt / (p.max_init_tries - 1) if p.max_init_tries > 1 else 1.0
    site, t = arm_site(np.asarray(task.arm, float), np.asarray(task.hang_point, float),
                       rng.uniform(-1.0, 1.0) * p.slide_noise_m * reach)
    n = np.array([-t[2], 0.0, t[0]]) if abs(t[1]) < 0.99 else np.array([0.0, 0.0, 1.0])
    n -= np.dot(n, t) * t
    n /= np.linalg.norm(n)
    r0 = np.stack([t, np.cross(n, t), n], axis=1)
    roll = np.radians(rng.uniform(-p.roll_noise_deg, p.roll_noise_deg))
    c, s = np.cos(roll), np.sin(roll)
    rot = random_rotation_small(rng, p.pose_noise_deg) @ r0 @ np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    drop = task.arm_radius_m + p.release_gap_m - task.aperture_clearance_m
    out = np.eye(4)
    out[:3, :3], out[:3, 3] = rot, site + n * drop
    return out


def reference_task(support, ref, src: Path, seed: int, p: ContactSimParams) -> HangTask:
    """The ``reference_on_support`` run of the reference object ``ref`` (a row of the objects
    table) on ``support`` (a row of the supports table); ``src``: the mesh_gen folder their
    paths are relative to."""
    return HangTask(support.support_id, "reference_on_support", ref.object_id,
                    str(src / ref.urdf_path), ref.aperture_clearance_m, support.support_id,
                    str(src / support.urdf_path), tuple(map(tuple, support.arm_centreline)),
                    tuple(support.hang_point), support.radius_m, seed, p)


def _clear(world: World, obj: int, others: list[int], clearance: float) -> bool:
    return all(world.min_distance(obj, b) >= clearance for b in others)


def _push_clear(world: World, obj: int, support: int, clearance: float) -> float:
    """Move ``obj`` along the closest-point normal until it clears ``support`` by
    ``clearance``; returns the final distance."""
    for _ in range(20):
        pts = pb.getClosestPoints(obj, support, 0.05, physicsClientId=world.cid)
        d = min(p[8] for p in pts)
        if d >= clearance:
            return d
        closest = min(pts, key=lambda p: p[8])
        normal_world = np.asarray(closest[7])  # on B (support), pointing toward A (object)
        n_support = SUPPORT_POSE_WORLD[:3, :3].T @ normal_world
        t = world.pose_support(obj)
        t[:3, 3] += n_support * (clearance - d + 1e-4)
        world.set_pose_support(obj, t)
    return world.min_distance(obj, support)


def _medoid(points: list[np.ndarray], tol: float) -> tuple[int, int]:
    """Index of the point with most neighbours within ``tol`` (ties: smallest summed
    distance, then lowest index), and that neighbour count (itself included)."""
    p = np.asarray(points)
    d = np.linalg.norm(p[:, None] - p[None], axis=2)
    support = (d <= tol).sum(1)
    key = [(-support[i], d[i].sum(), i) for i in range(len(p))]
    best = min(key)[2]
    return best, int(support[best])


def simulate_hangs(task: HangTask) -> dict:
    """Run ``task``; returns one row of :data:`skt_lib.schemas.CONTACTS`."""
    p = task.params
    rng = item_rng(task.seed, "contact_sim", task.item_id)
    pert = perturbation(p)
    with World(p.dt, p.solver_iterations) as world:
        wall = world.add_wall()
        if task.support_urdf:
            support = world.load(task.support_urdf, np.eye(4), fixed=True, friction=p.friction)
        else:
            support = add_rod(world, p.rod_radius_m, p.friction)
        obj = world.load(task.object_urdf, _PARK, fixed=False, friction=p.friction,
                         linear_damping=p.linear_damping, angular_damping=p.angular_damping)

        trials: list[tuple[HangCheck, np.ndarray]] = []
        reasons: Counter = Counter()
        for _ in range(p.n_drops):
            for attempt in range(p.max_init_tries):
                world.set_pose_support(obj, release_pose(rng, task, attempt))
                if _clear(world, obj, [support, wall], p.init_clearance_m):
                    break
            else:
                reasons["no_release_pose"] += 1
                continue
            world.set_gravity_support((0.0, 0.0, -G))
            world.step(p.drop_steps)
            perturb(world, pert)
            check = check_hang(world, obj, support, pert)
            if check.ok:
                trials.append((check, world.pose_support(obj)))
            else:
                reasons[check.reason] += 1

        row = _empty_row(task, n_success=len(trials))
        if not trials:
            row["failure_reason"] = reasons.most_common(1)[0][0] if reasons else "no_release_pose"
            return row
        key = [c.contact_support if task.support_urdf else c.contact_object for c, _ in trials]
        best, n_consistent = _medoid(key, p.consistency_tol_m)
        check, pose = trials[best]

        # the goal: the kept hang, nudged clear of the support, must hang again from rest
        world.set_pose_support(obj, pose)
        clearance = _push_clear(world, obj, support, p.goal_clearance_m)
        goal = world.pose_support(obj)
        perturb(world, pert)
        again = check_hang(world, obj, support, pert)
        row.update(n_consistent=n_consistent, goal_clearance_m=float(clearance))
        if clearance < p.goal_clearance_m * 0.5:
            row["failure_reason"] = "goal_not_clear"
            return row
        if not again.ok:
            row["failure_reason"] = f"goal_unstable_{again.reason}"
            return row
        pos, quat = matrix_pose(goal)
        row.update(
            ok=True,
            failure_reason="",
            contact_support=[float(v) for v in check.contact_support],
            contact_object=[float(v) for v in check.contact_object],
            hang_position=[float(v) for v in pos],
            hang_quat=[float(v) for v in quat],
        )
        return row


def _empty_row(task: HangTask, n_success: int) -> dict:
    nan3 = [float("nan")] * 3
    return {
        "item_id": task.item_id,
        "kind": task.kind,
        "object_id": task.object_id,
        "support_id": task.support_id,
        "ok": False,
        "failure_reason": "",
        "n_attempts": task.params.n_drops,
        "n_success": n_success,
        "n_consistent": 0,
        "contact_support": nan3,
        "contact_object": nan3,
        "hang_position": nan3,
        "hang_quat": [float("nan")] * 4,
        "goal_clearance_m": float("nan"),
    }
