"""Grasps (the paper's fixed keypoint→end-effector transform ``T_kpt_ee``) and the per-trial
grasp chooser.

A grasp candidate approaches the lowest part of the object as it hangs: the approach axis
(hand +z) is keypoint +x turned about keypoint +z by ``yaw`` (0: from behind, along the
motion into the hang; ±90: from the side; 180: from in front), pitched down by ``pitch``
(the hand comes from above), with the hand rolled by ``roll`` about that axis; the grasp
target (between the fingertips) sits on the approach line through the lowest band, short of
the object by a standoff, so that the hand behind it is clear of the object. Candidates
come in a fixed order (yaw-major, then pitch, then roll, as listed in params), then, tried
last, approaches from directions spread over the whole sphere (from below and from straight
above too: where a curl turns the object by more than a right angle, the one approach that
stays within the arm's reach may be one the pitches never give);
:func:`choose_grasp` takes the first one for which the set-up IK finds a joint path along
the whole executed path, with the arm clear of the support and the wall along it and clear
of the object at the start.
"""

from collections import Counter
from dataclasses import dataclass

import numpy as np

from skt_lib.geometry.se3 import invert, transform_points
from skt_lib.sim.robot import FINGER_OPEN_M, IKFailure, Panda, rank
from skt_lib.sim.world import SUPPORT_POSE_WORLD, World

#: Radius of the cylinder along the approach that the hand (palm, fingers) sweeps, m.
HAND_RADIUS_M = 0.06


@dataclass(frozen=True)
class Grasp:
    label: str  # e.g. "pitch45_roll0"
    kpt_ee: tuple[float, ...]  # 16 floats, row-major 4×4: grasp target in the keypoint frame

    def matrix(self) -> np.ndarray:
        return np.asarray(self.kpt_ee, float).reshape(4, 4)


@dataclass(frozen=True)
class GraspChoice:
    """A reachable grasp: ``index`` into the candidates, and its joint path ``(M, 7)``."""

    index: int
    grasp: Grasp
    joints: np.ndarray


@dataclass(frozen=True)
class GraspFailure:
    """No candidate is reachable: one :class:`IKFailure` per candidate, in candidate order."""

    grasps: tuple[Grasp, ...]
    failures: tuple[IKFailure, ...]

    def describe(self) -> str:
        """One line: how many candidates failed each check, and the furthest failure."""
        counts = Counter(f.check for f in self.failures)
        best = max(range(len(self.failures)), key=lambda i: (rank(self.failures[i]), -i))
        return (f"no reachable grasp ({len(self.failures)} tried: "
                + ", ".join(f"{n} {c}" for c, n in sorted(counts.items()))
                + f"); furthest: {self.grasps[best].label} {self.failures[best].describe()}")


def grasp_in_keypoint(vertices: np.ndarray, keypoint: np.ndarray, pitch_deg: float,
                      roll_deg: float = 0.0, band_m: float = 0.02, standoff_m: float = 0.01,
                      yaw_deg: float = 0.0, hand_radius_m: float = HAND_RADIUS_M) -> np.ndarray:
    """Grasp target pose (4×4) in the keypoint frame (module docstring).

    ``vertices (N, 3)``: object mesh, object frame, m; ``keypoint (4, 4)``: keypoint frame in
    the object frame. The approach (hand +z) is keypoint +x turned by ``yaw_deg`` about
    keypoint +z (90: along +y, from the side; 180: along −x) and pitched down by
    ``pitch_deg``. The grasp target lies on the approach line through the centre of the
    lowest ``band_m`` of the object, ``standoff_m`` before the first object point within
    ``hand_radius_m`` of that line, so the hand behind it is clear of the object. Roll 0 keeps
    the hand's y axis along keypoint −y turned by the yaw."""
    p, r, y = np.radians(pitch_deg), np.radians(roll_deg), np.radians(yaw_deg)
    pitched = np.array([[np.sin(p), 0.0, np.cos(p)], [0.0, -1.0, 0.0],
                        [np.cos(p), 0.0, -np.sin(p)]])
    yawed = np.array([[np.cos(y), -np.sin(y), 0.0], [np.sin(y), np.cos(y), 0.0], [0.0, 0.0, 1.0]])
    return _placed(vertices, keypoint, yawed @ pitched @ _about_z(r), band_m, standoff_m,
                   hand_radius_m)


def grasp_along(vertices: np.ndarray, keypoint: np.ndarray, approach: np.ndarray,
                roll_deg: float = 0.0, band_m: float = 0.02, standoff_m: float = 0.01,
                hand_radius_m: float = HAND_RADIUS_M) -> np.ndarray:
    """Grasp target pose (4×4) in the keypoint frame whose approach (hand +z) is the unit
    vector ``approach`` (3,), keypoint frame, in any direction — from below and from straight
    above too, which :func:`grasp_in_keypoint`'s pitches (0 to 90° down) do not give. Roll 0
    puts the hand's x axis along keypoint +z × approach (along +z × keypoint +x when the
    approach is within 25° of ±z); placed as :func:`grasp_in_keypoint` places its target."""
    d = np.asarray(approach, float)
    d = d / np.linalg.norm(d)
    ref = np.array([0.0, 0.0, 1.0]) if abs(d[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    x = np.cross(ref, d)
    x /= np.linalg.norm(x)
    rot = np.stack([x, np.cross(d, x), d], axis=1)
    return _placed(vertices, keypoint, rot @ _about_z(np.radians(roll_deg)), band_m, standoff_m,
                   hand_radius_m)


def sphere_directions(n: int) -> np.ndarray:
    """``n`` unit vectors (n, 3) spread evenly over the sphere (a Fibonacci lattice, from +z
    down to −z): the same list every time."""
    i = np.arange(n) + 0.5
    z = 1.0 - 2.0 * i / n
    r = np.sqrt(1.0 - z * z)
    a = np.pi * (1.0 + np.sqrt(5.0)) * i
    return np.stack([r * np.cos(a), r * np.sin(a), z], axis=1)


def _about_z(angle: float) -> np.ndarray:
    return np.array([[np.cos(angle), -np.sin(angle), 0.0], [np.sin(angle), np.cos(angle), 0.0],
                     [0.0, 0.0, 1.0]])


def _placed(vertices, keypoint, rot, band_m, standoff_m, hand_radius_m) -> np.ndarray:
    """The grasp with hand orientation ``rot`` (3×3, keypoint frame; column 2 the approach),
    its target on the approach line through the centre of the object's lowest ``band_m``,
    ``standoff_m`` before the first object point within ``hand_radius_m`` of that line."""
    v = transform_points(invert(keypoint), np.asarray(vertices, float))
    centre = v[v[:, 2] <= v[:, 2].min() + band_m].mean(axis=0)
    d = rot[:, 2]
    along = (v - centre) @ d
    lateral = np.linalg.norm((v - centre) - along[:, None] * d, axis=1)
    t = np.eye(4)
    t[:3, :3] = rot
    t[:3, 3] = centre + (float(along[lateral <= hand_radius_m].min(initial=0.0)) - standoff_m) * d
    return t


def grasp_candidates(vertices: np.ndarray, keypoint: np.ndarray, pitches_deg, rolls_deg,
                     band_m: float = 0.02, standoff_m: float = 0.01,
                     yaws_deg=(0.0,), sphere: int = 0) -> tuple[Grasp, ...]:
    """Every (yaw, pitch, roll) grasp, yaw-major, then pitch, in the given orders; then, with
    ``sphere`` > 0, a grasp along each of :func:`sphere_directions` (``sphere``) for each
    roll (direction-major): tried last, so a trial that a (yaw, pitch, roll) grasp serves runs
    as it would without them."""
    def grasp(label: str, t: np.ndarray) -> Grasp:
        # Python floats: every trial task pickles a few hundred of them
        return Grasp(label, tuple(t.ravel().tolist()))

    grid = tuple(
        grasp(f"pitch{p:g}_roll{r:g}" if y == 0 else f"yaw{y:g}_pitch{p:g}_roll{r:g}",
              grasp_in_keypoint(vertices, keypoint, p, r, band_m, standoff_m, y))
        for y in yaws_deg for p in pitches_deg for r in rolls_deg)
    return grid + tuple(
        grasp(f"sphere{i}_roll{r:g}", grasp_along(vertices, keypoint, d, r, band_m, standoff_m))
        for i, d in enumerate(sphere_directions(sphere)) for r in rolls_deg)


def choose_grasp(world: World, robot: Panda, path: np.ndarray, grasps: tuple[Grasp, ...],
                 fixed: list[int], obj: int, tol_m: float, tol_rad: float, max_jump_rad: float,
                 restarts: int, clearance_m: float, check_every: int = 4) -> GraspChoice | GraspFailure:
    """The first of ``grasps`` for which :meth:`Panda.joint_path` tracks every keypoint
    frame of ``path (M, 4, 4)`` (support frame, execution order) within ``tol_m``/``tol_rad``
    and ``max_jump_rad``, with the arm at least ``clearance_m`` (PyBullet distance) from
    every body of ``fixed`` (support, wall) at the start pose and at every ``check_every``-th
    pose of the path and its last, and from ``obj`` (placed at its start pose: the hand
    holds it at a constant offset) at the start. Kinematic only (teleports the arm). Leaves
    the arm at the chosen path's start."""
    if not grasps:
        raise ValueError("grasps: no candidates")

    def clear(q: np.ndarray, bodies) -> bool:
        robot.reset(q, FINGER_OPEN_M)
        return all(world.min_distance(robot.body, b) >= clearance_m for b in bodies)

    def start_ok(q: np.ndarray) -> bool:
        return clear(q, [*fixed, obj])

    def first_blocked(joints: np.ndarray) -> int:
        checked = [*range(0, len(joints), check_every), len(joints) - 1]
        return next((k for k in checked if not clear(joints[k], fixed)), -1)

    failures = []
    for i, g in enumerate(grasps):
        kpt_ee = g.matrix()
        targets = SUPPORT_POSE_WORLD @ (path @ kpt_ee)  # = to_world(ξ · T_kpt_ee), (M, 4, 4)
        out = robot.joint_path(targets, tol_m, tol_rad, max_jump_rad, restarts, start_ok, first_blocked)
        if isinstance(out, IKFailure):
            failures.append(out)
            continue
        return GraspChoice(i, g, out)
    return GraspFailure(tuple(grasps), tuple(failures))

