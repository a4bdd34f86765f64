"""The hanging perturbation and the strict success predicate (docs/design.md §5).

After an object is released: perturb — gravity tilted ±``accel`` along the wall (support
±y) and ``accel`` outward from the wall (support +x), on top of −9.81 z, for
``steps_per_direction`` steps each — then settle under normal gravity for ``settle_steps``.
Gravity is reset to normal before returning, so nothing leaks into the next trial.

Success iff, at the end (:func:`check_hang`, first failing check wins):

1. the object touches neither the floor (``touches_floor``) nor the robot (``touches_robot``);
2. it touches the supporting item (``no_contact``);
3. it is at rest (``not_at_rest``: still swinging or sliding off): observed for a further
   ``rest_window_steps`` under normal gravity, its centre of mass strays at most
   ``rest_speed_m_s`` × window and its orientation at most ``rest_angular_speed_rad_s`` ×
   window from where the window began (a mean speed: robust to contact jitter, which the
   instantaneous velocity is not);
4. it touches the hanging part of the item, not only the wall plate (support-frame
   ``x ≤`` :data:`PLATE_X_M`; ``on_wall_plate``);
5. it hangs below the support: its centre of mass is lower than the supporting contact
   (the contact cluster off the plate carrying the largest normal force; ``perched``).
"""

from dataclasses import dataclass

import numpy as np
import pybullet as pb
from scipy.cluster.hierarchy import fcluster, linkage

from skt_lib.geometry.supports import PLATE_THICKNESS_M
from skt_lib.sim.world import SUPPORT_POSE_WORLD, World

G = 9.81
#: Contacts with the support at support-frame x ≤ this are on the wall plate (its front
#: face at x = PLATE_THICKNESS_M, plus 1 mm for PyBullet's contact margin).
PLATE_X_M = PLATE_THICKNESS_M + 0.001


@dataclass(frozen=True)
class Perturbation:
    """The perturbation and the at-rest thresholds of the predicate (``contact_sim.perturb``)."""

    accel_m_s2: float  # sideways / outward gravity tilt, m/s² (4.0 on 9.81: ≈ 22°)
    steps_per_direction: int  # physics steps per tilt direction
    settle_steps: int  # physics steps under normal gravity at the end
    rest_speed_m_s: float  # at rest: mean centre-of-mass speed over the window ≤ this, m/s
    rest_angular_speed_rad_s: float  # at rest: mean angular speed over the window ≤ this, rad/s
    rest_window_steps: int  # physics steps the at-rest check observes the object


@dataclass(frozen=True)
class HangCheck:
    ok: bool
    #: "ok", "touches_floor", "touches_robot", "no_contact", "not_at_rest",
    #: "on_wall_plate", "perched"
    reason: str
    contact_support: np.ndarray | None = None  # supporting contact, support frame (3,)
    contact_object: np.ndarray | None = None  # the same point in the object's link frame (3,)


def perturb_phases(p: Perturbation) -> list[tuple[tuple[float, float, float], int]]:
    """(gravity in the support frame, steps) per phase; the last one restores normal gravity."""
    a = p.accel_m_s2
    tilted = [((0.0, a, -G), p.steps_per_direction), ((0.0, -a, -G), p.steps_per_direction),
              ((a, 0.0, -G), p.steps_per_direction)]
    return tilted + [((0.0, 0.0, -G), p.settle_steps)]


def perturb(world: World, p: Perturbation) -> None:
    for gravity, steps in perturb_phases(p):
        world.set_gravity_support(gravity)
        world.step(steps)


def supporting_cluster(points: np.ndarray, forces: np.ndarray, radius: float = 0.005) -> np.ndarray:
    """Force-weighted centre of the contact cluster carrying the largest total normal force.

    ``points (K, 3)``, ``forces (K,)`` newtons; single-linkage clusters at ``radius`` metres.
    """
    points, forces = np.asarray(points, float), np.asarray(forces, float)
    if len(points) == 0:
        raise ValueError("points: no contacts")
    if len(points) == 1:
        return points[0].copy()
    labels = fcluster(linkage(points, "single"), t=radius, criterion="distance")
    best = max(set(labels), key=lambda k: (forces[labels == k].sum(), -k))
    m = labels == best
    w = forces[m] if forces[m].sum() > 0 else np.ones(m.sum())
    return (points[m] * w[:, None]).sum(0) / w.sum()


def observe_motion(world: World, body: int, steps: int, every: int = 10) -> tuple[float, float]:
    """Step ``steps`` more under normal gravity; (mean speed m/s, mean angular speed rad/s)
    over them: the largest distance of the centre of mass, and the largest rotation angle,
    from its pose at the start (sampled every ``every`` steps), divided by the duration."""
    world.set_gravity_support((0.0, 0.0, -G))
    p0, q0 = pb.getBasePositionAndOrientation(body, physicsClientId=world.cid)
    inv0 = pb.invertTransform([0, 0, 0], q0)[1]
    dist = ang = 0.0
    done = 0
    while done < steps:
        n = min(every, steps - done)
        world.step(n)
        done += n
        p, q = pb.getBasePositionAndOrientation(body, physicsClientId=world.cid)
        dq = pb.multiplyTransforms([0, 0, 0], inv0, [0, 0, 0], q)[1]
        dist = max(dist, float(np.linalg.norm(np.subtract(p, p0))))
        ang = max(ang, 2.0 * float(np.arccos(np.clip(abs(dq[3]), 0.0, 1.0))))
    duration = max(steps, 1) * world.dt
    return dist / duration, ang / duration


def check_hang(world: World, obj: int, support: int, p: Perturbation,
               robot: int | None = None) -> HangCheck:
    """The predicate (module docstring) — call it after :func:`perturb`. It first observes
    the object for ``p.rest_window_steps`` steps (so it advances the simulation), then judges
    the state at the end. ``robot``: a body the object must not touch (the gripper)."""
    v, w = observe_motion(world, obj, p.rest_window_steps)
    if world.floor is not None and world.contacts(obj, world.floor):
        return HangCheck(False, "touches_floor")
    if robot is not None and world.contacts(obj, robot):
        return HangCheck(False, "touches_robot")
    cps = world.contacts(obj, support)
    if not cps:
        return HangCheck(False, "no_contact")
    if v > p.rest_speed_m_s or w > p.rest_angular_speed_rad_s:
        return HangCheck(False, "not_at_rest")
    on_obj = np.array([c[5] for c in cps])  # positionOnA (object), world
    on_sup = np.array([c[6] for c in cps])  # positionOnB (support), world
    x_support = (on_sup - SUPPORT_POSE_WORLD[:3, 3]) @ SUPPORT_POSE_WORLD[:3, 0]
    hanging = x_support > PLATE_X_M
    if not hanging.any():
        return HangCheck(False, "on_wall_plate")
    forces = np.array([c[9] for c in cps])
    c_world = supporting_cluster(on_obj[hanging], forces[hanging])
    c_support = world.point_to_support(c_world)
    t_obj = world.pose_support(obj)
    c_object = (np.linalg.inv(t_obj) @ np.append(c_support, 1.0))[:3]
    if world.com_support(obj)[2] >= c_support[2]:
        return HangCheck(False, "perched", c_support, c_object)
    return HangCheck(True, "ok", c_support, c_object)
