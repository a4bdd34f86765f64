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
checked to survive the perturbation again from rest — a support's under the evaluation's
physics (``sim_eval``'s undamped tilts, :func:`perturb_as_evaluated`), so that no goal of the
planner is a hang the evaluation would drop. Where the medoid fails that, the next most
consistent hang is tried (``goal_rank``: which one became the goal); where none passes, the
drops are made again at hang points moved back along the arm toward the wall
(:data:`FALLBACK_SHIFTS_M`; ``goal_shift_m``).
"""

import dataclasses
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pybullet as pb

from skt_lib.config.contact_sim import ContactSimParams
from skt_lib.geometry.se3 import matrix_pose, pose_matrix, random_rotation_small
from skt_lib.seeding import item_rng
from skt_lib.sim.hanging import G, HangCheck, Perturbation, check_hang, perturb, perturb_phases
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
    #: the evaluation's object damping (linear, angular, settle linear, settle angular; 1/s,
    #: ``sim_eval``'s): a support's goal is judged by it (:func:`eval_damping`); ``None``
    #: judges it at ``params``' damping throughout (objects on the rod)
    eval_damping: tuple[float, float, float, float] | None = None


def eval_damping(params) -> tuple[float, float, float, float]:
    """The object damping ``sim_eval`` perturbs and settles at (``params``: all stages'):
    the physics a reference hang must pass to become a planner's goal."""
    e = params.sim_eval
    return (e.linear_damping, e.angular_damping, e.settle_linear_damping, e.settle_angular_damping)


def perturb_as_evaluated(world: World, obj: int, pert: Perturbation,
                         damping: tuple[float, float, float, float]) -> None:
    """:func:`~skt_lib.sim.hanging.perturb` with ``obj`` at the evaluation's damping: the
    tilts at ``damping[:2]``, the settle at ``damping[2:]`` (``sim_eval``'s executor does the
    same); ``obj``'s damping is left at the settle's."""
    for i, (gravity, steps) in enumerate(perturb_phases(pert)):
        lin, ang = damping[2:] if i == len(perturb_phases(pert)) - 1 else damping[:2]
        pb.changeDynamics(obj, -1, linearDamping=lin, angularDamping=ang, physicsClientId=world.cid)
        world.set_gravity_support(gravity)
        world.step(steps)


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


def reference_task(support, ref, src: Path, seed: int, p: ContactSimParams,
                   damping: tuple[float, float, float, float]) -> HangTask:
    """The ``reference_on_support`` run of the reference object ``ref`` (a row of the objects
    table) on ``support`` (a row of the supports table); ``src``: the mesh_gen folder their
    paths are relative to; ``damping``: the evaluation's (:func:`eval_damping`)."""
    return HangTask(support.support_id, "reference_on_support", ref.object_id,
                    str(src / ref.urdf_path), ref.aperture_clearance_m, support.support_id,
                    str(src / support.urdf_path), tuple(map(tuple, support.arm_centreline)),
                    tuple(support.hang_point), support.radius_m, seed, p, damping)


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


def _by_consistency(points: list[np.ndarray], tol: float) -> list[tuple[int, int]]:
    """``(index, neighbours within tol, itself included)`` of every point, the medoid first:
    most neighbours, then smallest summed distance, then lowest index."""
    p = np.asarray(points)
    d = np.linalg.norm(p[:, None] - p[None], axis=2)
    support = (d <= tol).sum(1)
    order = sorted(range(len(p)), key=lambda i: (-support[i], d[i].sum(), i))
    return [(i, int(support[i])) for i in order]


#: Where no hang of the drops passes the evaluation's physics, a support's drops are made
#: again this far (path length) back along the arm toward the wall, nearest first (m): a
#: ring that slides off a peg's end under the undamped tilts stays nearer the wall.
FALLBACK_SHIFTS_M = (0.01, 0.02, 0.03)


def _drops(world: World, obj: int, support: int, wall: int, task: HangTask,
           rng: np.random.Generator, pert: Perturbation) -> tuple[list, Counter]:
    """``n_drops`` releases at ``task``'s hang point, dropped, perturbed (the drops' damping)
    and judged: the successful ``(check, pose)`` and the failure reasons."""
    p = task.params
    trials, reasons = [], Counter()
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
    return trials, reasons


def _goal(world: World, obj: int, support: int, task: HangTask, trials: list,
          pert: Perturbation) -> dict:
    """The goal among ``trials``: the most consistent hang, nudged clear of the support, that
    hangs again from rest — a support's under the evaluation's physics (undamped tilts), so
    no goal is one sim_eval would drop; where one does not, the next most consistent is
    tried. A dict: ``ok``, ``failure_reason``, ``goal_rank``, ``n_consistent``,
    ``goal_clearance_m``, and when ok ``check`` and ``goal`` (pose, support frame)."""
    p = task.params
    key = [c.contact_support if task.support_urdf else c.contact_object for c, _ in trials]
    out = {"ok": False, "goal_rank": -1}
    for rank, (best, n_consistent) in enumerate(_by_consistency(key, p.consistency_tol_m)):
        check, pose = trials[best]
        world.set_pose_support(obj, pose)
        clearance = _push_clear(world, obj, support, p.goal_clearance_m)
        goal = world.pose_support(obj)
        if task.eval_damping is None:
            perturb(world, pert)
        else:
            perturb_as_evaluated(world, obj, pert, task.eval_damping)
        again = check_hang(world, obj, support, pert)
        if task.eval_damping is not None:  # back to the drops' damping
            pb.changeDynamics(obj, -1, linearDamping=p.linear_damping,
                              angularDamping=p.angular_damping, physicsClientId=world.cid)
        out.update(n_consistent=n_consistent, goal_clearance_m=float(clearance))
        if clearance < p.goal_clearance_m * 0.5:
            out["failure_reason"] = "goal_not_clear"
        elif not again.ok:
            out["failure_reason"] = f"goal_unstable_{again.reason}"
        else:
            return out | {"ok": True, "failure_reason": "", "goal_rank": rank, "check": check,
                          "goal": goal}
    return out


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

        trials, reasons = _drops(world, obj, support, wall, task, rng, pert)
        row = _empty_row(task, n_success=len(trials))
        if not trials:
            row["failure_reason"] = reasons.most_common(1)[0][0] if reasons else "no_release_pose"
            return row
        found, shift = _goal(world, obj, support, task, trials, pert), 0.0
        if not found["ok"] and task.eval_damping is not None:
            # no hang here passes the evaluation: another hang point, back along the arm
            for shift in FALLBACK_SHIFTS_M:
                site, _ = arm_site(np.asarray(task.arm, float), np.asarray(task.hang_point, float),
                                   -shift)
                moved = dataclasses.replace(task, hang_point=tuple(map(float, site)))
                more, _ = _drops(world, obj, support, wall, moved, rng, pert)
                if more:
                    found = _goal(world, obj, support, moved, more, pert)
                    if found["ok"]:
                        break
        row.update(failure_reason=found.get("failure_reason", row["failure_reason"]),
                   goal_rank=found["goal_rank"], goal_shift_m=shift if found["ok"] else float("nan"))
        if "n_consistent" in found:
            row.update(n_consistent=found["n_consistent"], goal_clearance_m=found["goal_clearance_m"])
        if not found["ok"]:
            return row
        check, goal = found["check"], found["goal"]
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
        "goal_rank": -1,
        "goal_shift_m": float("nan"),
    }
