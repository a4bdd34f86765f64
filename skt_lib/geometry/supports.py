"""Procedural supporting items (hooks, pegs, racks) in the support frame.

Support frame (docs/design.md §3): origin at the mounting point on the wall surface, +x out of the
wall toward the robot, +z up, +y = z × x. Every item is a wall plate (``x ∈ [0, 1 cm]``)
plus *strokes* — tubes of round or square section along polylines — and optional knobs.
Stroke 0 is the hanging arm. Hooks lie in the x–z plane; racks add strokes along y.

Difficulty comes from geometry, not from the family name (see :func:`measure_difficulty`):
the *blocking height* of the hook beyond its hang point, measured perpendicular to the arm
at that point (how far a straight-in approach along the arm must lift over a tip, knob or
curl), the *clearance* above the arm (narrow gaps), and the tip's total turning (curls).
"""

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from skt_lib.config import LEVELS
from skt_lib.config.mesh_gen import MeshGenParams
from skt_lib.errors import GenerationFailed
from skt_lib.geometry.convex import Mesh, box, norm3, rowdot3, rownorm3, sphere, tube

PLATE_THICKNESS_M = 0.01
#: The hang point is searched at least this far from the wall, so a hung object clears it.
HANG_MIN_X_M = 0.025
_ARC_STEP_DEG = 12.0
_Y = np.array([0.0, 1.0, 0.0])
_Z = np.array([0.0, 0.0, 1.0])


@dataclass(frozen=True, eq=False)
class Stroke:
    """A tube along ``points (M, 3)`` metres with section half-width ``radius``."""

    points: np.ndarray
    radius: float
    square: bool
    side: tuple[float, float, float] = (0.0, 1.0, 0.0)


@dataclass(frozen=True, eq=False)
class SupportShape:
    family: str
    strokes: tuple[Stroke, ...]
    knobs: tuple[tuple[tuple[float, float, float], float], ...] = ()
    plate_half_y: float = 0.02

    def parts(self) -> list[Mesh]:
        """Convex parts: the wall plate, one part per stroke segment, one per knob."""
        starts = np.array([s.points[0] for s in self.strokes])
        z_lo, z_hi = starts[:, 2].min() - 0.025, starts[:, 2].max() + 0.025
        plate = box(
            [PLATE_THICKNESS_M / 2, 0.0, (z_lo + z_hi) / 2],
            [PLATE_THICKNESS_M / 2, self.plate_half_y, (z_hi - z_lo) / 2],
        )
        parts = [plate]
        for s in self.strokes:
            parts += tube(s.points, s.radius, s.square, s.side)
        parts += [sphere(c, r) for c, r in self.knobs]
        return parts


class _Path:
    """Turtle in the x–z plane at fixed y; heading angle measured from +x toward +z."""

    def __init__(self, start, heading_deg: float):
        self.points = [np.asarray(start, dtype=np.float64)]
        self.phi = math.radians(heading_deg)

    def straight(self, length: float) -> "_Path":
        d = np.array([math.cos(self.phi), 0.0, math.sin(self.phi)])
        self.points.append(self.points[-1] + length * d)
        return self

    def arc(self, radius: float, sweep_deg: float) -> "_Path":
        """Turn by ``sweep_deg`` (positive: counter-clockwise, i.e. upward when heading +x)."""
        sign = 1.0 if sweep_deg > 0 else -1.0
        left = np.array([-math.sin(self.phi), 0.0, math.cos(self.phi)])
        center = self.points[-1] + sign * radius * left
        n = max(1, math.ceil(abs(sweep_deg) / _ARC_STEP_DEG))
        a0 = self.phi - sign * math.pi / 2
        for k in range(1, n + 1):
            a = a0 + sign * math.radians(sweep_deg * sign) * k / n
            self.points.append(center + radius * np.array([math.cos(a), 0.0, math.sin(a)]))
        self.phi += math.radians(sweep_deg)
        return self

    def array(self) -> np.ndarray:
        return np.array(self.points)


# ---------------------------------------------------------------- families
# Each takes (rng, r, square, rise, p) and returns a SupportShape; ``rise`` is the blocking
# height the sampler aims for (the measured value decides the level).

_WALL = (PLATE_THICKNESS_M, 0.0, 0.0)  # strokes start on the plate's front face


def _u(rng, lo, hi) -> float:
    return float(rng.uniform(lo, hi))


def _peg(rng, r, sq, rise, p):
    pts = _Path(_WALL, _u(rng, 3, 20)).straight(_u(rng, 0.07, 0.13)).array()
    return SupportShape("peg", (Stroke(pts, r, sq),))


def _angled_peg(rng, r, sq, rise, p):
    pts = _Path(_WALL, _u(rng, 20, 45)).straight(_u(rng, 0.06, 0.11)).array()
    return SupportShape("angled_peg", (Stroke(pts, r, sq),))


def _knob_peg(rng, r, sq, rise, p):
    pts = _Path(_WALL, _u(rng, 3, 15)).straight(_u(rng, 0.06, 0.12)).array()
    knob = min(r + rise, 0.9 * p.object_rod_radius_m)
    return SupportShape("knob_peg", (Stroke(pts, r, sq),), knobs=((tuple(pts[-1]), knob),))


def _l_hook(rng, r, sq, rise, p):
    bend = max(1.5 * r, 0.006)
    path = _Path(_WALL, _u(rng, -6, 4)).straight(_u(rng, 0.05, 0.10)).arc(bend, 90)
    path.straight(max(rise - bend, 0.003))
    return SupportShape("l_hook", (Stroke(path.array(), r, sq),))


def _j_path(rng, rise, heading, length):
    rho = _u(rng, 0.012, 0.025)
    sweep = _u(rng, 70, 150)
    base = rho * (1 - math.cos(math.radians(sweep)))
    path = _Path(_WALL, heading).straight(length)
    if rise <= base:  # shallower upturn: shrink the sweep, no straight tip
        sweep = math.degrees(math.acos(max(-1.0, 1 - rise / rho)))
        return path.arc(rho, max(sweep, 5.0))
    path.arc(rho, sweep)
    return path.straight((rise - base) / max(math.sin(math.radians(sweep)), 0.3))


def _j_hook(rng, r, sq, rise, p):
    path = _j_path(rng, rise, _u(rng, -8, 0), _u(rng, 0.04, 0.09))
    return SupportShape("j_hook", (Stroke(path.array(), r, sq),))


def _curled_hook(rng, r, sq, rise, p):
    path = _Path(_WALL, _u(rng, -6, 0)).straight(_u(rng, 0.05, 0.09))
    path.arc(_u(rng, 0.012, 0.022), _u(rng, p.curl_very_hard_deg + 5, 250))
    return SupportShape("curled_hook", (Stroke(path.array(), r, sq),))


def _upturned_tip(rng, r, sq, rise, p):
    down, up = _u(rng, 15, 35), _u(rng, 20, 60)
    path = _Path(_WALL, -down).straight(_u(rng, 0.04, 0.08)).arc(0.008, down + up)
    path.straight(max(rise / math.sin(math.radians(up)), 0.004))
    return SupportShape("upturned_tip", (Stroke(path.array(), r, sq),))


def _s_hook(rng, r, sq, rise, p):
    """A peg bent down into a drop and a J: an S-hook fused to its peg, in side view."""
    rho1, rho2 = _u(rng, 0.01, 0.018), _u(rng, 0.014, 0.024)
    tip_turn = _u(rng, 50, 110)  # tip heading above horizontal, past the bottom of the J
    path = _Path(_WALL, 0.0).straight(_u(rng, 0.03, 0.05)).arc(rho1, -90)
    path.straight(_u(rng, 0.02, 0.045)).arc(rho2, 90 + tip_turn)
    base = rho2 * (1 - math.cos(math.radians(tip_turn)))
    path.straight(max((rise - base) / math.sin(math.radians(tip_turn)), 0.004))
    return SupportShape("s_hook", (Stroke(path.array(), r, sq),))


def _double_hook(rng, r, sq, rise, p):
    lower = _j_path(rng, rise, _u(rng, -5, 5), _u(rng, 0.05, 0.09))
    dz = _u(rng, 0.03, 0.08)
    upper = _Path((_WALL[0], 0.0, dz), _u(rng, 15, 45)).straight(_u(rng, 0.03, 0.06))
    return SupportShape(
        "double_hook", (Stroke(lower.array(), r, sq), Stroke(upper.array(), r, sq))
    )


def _narrow_gap_hook(rng, r, sq, rise, p):
    """A J-hook with a bar from the wall reaching over its tip: objects thread through the
    gap between the bar and the tip."""
    lower = _j_path(rng, rise, _u(rng, -5, 0), _u(rng, 0.05, 0.09))
    pts = lower.array()
    tip = pts[np.argmax(pts[:, 2])]
    top = tip[2] + 2 * r + _u(rng, 0.5, 0.9) * p.narrow_gap_m
    upper = np.array([[_WALL[0], 0.0, top], [tip[0] + _u(rng, -0.01, 0.005), 0.0, top]])
    return SupportShape("narrow_gap_hook", (Stroke(pts, r, sq), Stroke(upper, r, sq)))


def _rack(rng, r, sq, rise, p):
    depth, spacing, half_y = _u(rng, 0.03, 0.05), _u(rng, 0.04, 0.06), 0.07
    heading, length = _u(rng, 5, 25), _u(rng, 0.05, 0.09)
    prongs = []
    for y in (0.0, -spacing, spacing):
        path = _Path((depth, y, 0.0), heading).straight(length)
        if rise > 0.002:
            path.arc(0.01, 90).straight(max(rise - 0.01, 0.003))
        prongs.append(Stroke(path.array(), r, sq))
    stands = [
        Stroke(np.array([[_WALL[0], y, 0.0], [depth, y, 0.0]]), r, sq) for y in (-half_y, half_y)
    ]
    bar = Stroke(np.array([[depth, -half_y, 0.0], [depth, half_y, 0.0]]), r, sq, (0.0, 0.0, 1.0))
    return SupportShape("rack", (*prongs, *stands, bar), plate_half_y=half_y + 0.01)


FAMILIES: dict[str, Callable] = {
    "peg": _peg,
    "angled_peg": _angled_peg,
    "knob_peg": _knob_peg,
    "l_hook": _l_hook,
    "j_hook": _j_hook,
    "curled_hook": _curled_hook,
    "upturned_tip": _upturned_tip,
    "s_hook": _s_hook,
    "double_hook": _double_hook,
    "narrow_gap_hook": _narrow_gap_hook,
    "rack": _rack,
}

#: Families tried for each target level; the measured level must match or it is redrawn.
LEVEL_FAMILIES = {
    "easy": ("peg", "angled_peg", "knob_peg", "rack", "l_hook"),
    "normal": ("knob_peg", "l_hook", "j_hook", "upturned_tip", "rack", "double_hook"),
    "hard": ("l_hook", "j_hook", "upturned_tip", "s_hook", "double_hook", "rack"),
    "very_hard": ("j_hook", "curled_hook", "s_hook", "narrow_gap_hook", "double_hook"),
}


# ---------------------------------------------------------------- difficulty
@dataclass(frozen=True)
class Difficulty:
    level: str
    blocking_height_m: float  # lift over tip/knob/curl beyond the hang point, ⊥ to the arm
    clearance_above_m: float  # free space between the arm (hang point → tip) and structure above it (1.0: none)
    tip_turn_deg: float  # total turning of the arm from the hang point to its tip
    hang_point: tuple[float, float, float] = field(default=(0.0, 0.0, 0.0))  # arm centreline
    hang_tangent: tuple[float, float, float] = field(default=(1.0, 0.0, 0.0))  # arm direction


def _densify(points: np.ndarray, step: float = 0.001) -> np.ndarray:
    out = [points[:1]]
    for a, b in zip(points[:-1], points[1:]):
        n = max(1, math.ceil(norm3(b - a) / step))
        out.append(a + (b - a) * (np.arange(1, n + 1)[:, None] / n))
    return np.vstack(out)


def measure_difficulty(shape: SupportShape, p: MeshGenParams) -> Difficulty:
    """Geometric difficulty of ``shape`` with the thresholds in ``p``."""
    arm = shape.strokes[0]
    pts = _densify(arm.points)
    seg = np.diff(pts, axis=0)
    s = np.concatenate([[0.0], np.cumsum(rownorm3(seg))])
    z_top = pts[:, 2] + arm.radius
    cand = np.flatnonzero(pts[:, 0] >= HANG_MIN_X_M)
    if len(cand) == 0:
        raise GenerationFailed("arm never reaches the hang region", "no_hang_region")
    # Lowest point of the arm; on a flat stretch the object slides nowhere, so take the far
    # end of that stretch (where a J/L bend starts), not its wall end.
    i = int(cand[np.argmin(z_top[cand])])
    zmin = z_top[i]
    while (i + 1 < len(seg) and z_top[i + 1] <= zmin + 1e-4
           and abs(seg[i][2]) < 0.035 * norm3(seg[i])):
        i += 1
    if i == len(pts) - 1:
        raise GenerationFailed("hang point at the very tip: objects would slide off", "slides_off")
    c = pts[i]
    t = seg[i - 1] if i > 0 else seg[i]  # arriving direction: the arm's, at a bend
    # no BLAS (``@``, ``np.dot``, vector ``np.linalg.norm``) and no numpy SIMD arccos here:
    # both round differently per CPU, and these numbers are recorded (see convex.py)
    t = t / norm3(t)
    n = np.array([-t[2], 0.0, t[0]])
    n /= norm3(n)
    heights = [float(rowdot3(pts[i + 1 :] - c, n).max())]
    heights += [float(rowdot3(np.asarray(k) - c, n)) + rk - arm.radius for k, rk in shape.knobs]
    blocking = max(0.0, *heights)

    dirs = np.vstack([t, seg[i:] / rownorm3(seg[i:])[:, None]])
    cos = np.clip(rowdot3(dirs[:-1] * dirs[1:], (1.0, 1.0, 1.0)), -1, 1)
    turn = math.degrees(math.fsum(math.acos(x) for x in cos.tolist()))

    # clearance: free space between the arm from the hang point to its tip and any other
    # structure above the arm line and not behind the hang point
    beyond = pts[i:]
    others = [(pts[(s < s[i] - 0.025)], arm.radius)]
    others += [(_densify(st.points), st.radius) for st in shape.strokes[1:]]
    clearance = 1.0
    for q, rq in others:
        if len(q) == 0:
            continue
        a, b = rowdot3(q - c, t), rowdot3(q - c, n)
        q = q[(a >= -0.01) & (b > arm.radius + rq)]
        if len(q):
            gap = rownorm3(q[:, None] - beyond[None]).min() - rq - arm.radius
            clearance = min(clearance, float(gap))

    level = int(np.searchsorted(np.asarray(p.level_rise_m), blocking, side="right"))
    if turn >= p.curl_very_hard_deg:
        level = 3
    if clearance < p.narrow_gap_m:
        level = min(level + 1, 3)
    return Difficulty(LEVELS[level], blocking, clearance, turn, tuple(float(v) for v in c),
                      tuple(float(v) for v in t))


def sample_support(
    rng: np.random.Generator, target: str, p: MeshGenParams, max_tries: int = 300
) -> tuple[SupportShape, Difficulty]:
    """Draw families and parameters until the *measured* level equals ``target``."""
    k = LEVELS.index(target)
    bands = [0.0, *p.level_rise_m, p.level_rise_m[-1] + 0.03]
    for _ in range(max_tries):
        family = LEVEL_FAMILIES[target][rng.integers(len(LEVEL_FAMILIES[target]))]
        lo, hi = bands[k], bands[k + 1]
        rise = _u(rng, lo + 0.1 * (hi - lo), hi - 0.1 * (hi - lo))
        r = _u(rng, *p.support_radius_m)
        square = bool(rng.random() < 0.3)
        try:
            shape = FAMILIES[family](rng, r, square, rise, p)
            diff = measure_difficulty(shape, p)
        except GenerationFailed:
            continue
        if diff.level == target:
            return shape, diff
    raise GenerationFailed(f"no {target} support after {max_tries} draws", "level_not_reached")
