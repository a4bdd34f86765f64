"""The hanging perturbation and the strict success predicate (DESIGN §5).

After an object is released: perturb — gravity tilted ±``accel`` along the wall (support
±y) and ``accel`` outward from the wall (support +x), on top of −9.81 z, for
``steps_per_direction`` steps each — then settle under normal gravity. Success iff the
object touches the supporting item, touches neither floor nor robot, and hangs below the
support (its centre of mass lower than the supporting contacts: not perched on top).
Gravity is reset to normal before returning, so nothing leaks into the next trial.
"""

from dataclasses import dataclass

import numpy as np
from scipy.cluster.hierarchy import fcluster, linkage

from skt_lib.sim.world import World

G = 9.81


@dataclass(frozen=True)
class Perturbation:
    accel_m_s2: float
    steps_per_direction: int
    settle_steps: int


@dataclass(frozen=True)
class HangCheck:
    ok: bool
    reason: str  # "ok", "touches_floor", "touches_robot", "no_contact", "perched"
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


def check_hang(world: World, obj: int, support: int, robot: int | None = None) -> HangCheck:
    """The predicate, evaluated on the current state (call after :func:`perturb`)."""
    if world.floor is not None and world.contacts(obj, world.floor):
        return HangCheck(False, "touches_floor")
    if robot is not None and world.contacts(obj, robot):
        return HangCheck(False, "touches_robot")
    cps = world.contacts(obj, support)
    if not cps:
        return HangCheck(False, "no_contact")
    on_obj = np.array([c[5] for c in cps])
    forces = np.array([c[9] for c in cps])
    c_world = supporting_cluster(on_obj, forces)
    c_support = world.point_to_support(c_world)
    t_obj = world.pose_support(obj)
    c_object = (np.linalg.inv(t_obj) @ np.append(c_support, 1.0))[:3]
    if world.com_support(obj)[2] >= c_support[2]:
        return HangCheck(False, "perched", c_support, c_object)
    return HangCheck(True, "ok", c_support, c_object)
