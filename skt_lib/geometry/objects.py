"""Procedural hangable objects, each with a hanging aperture.

Object frame: origin at the aperture centre, aperture axis +x (a rod along x through the
origin passes through the aperture), +z up when the object hangs from that rod. Bodies
hang toward -z. Metres.
"""

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull

from skt_lib.config.mesh_gen import MeshGenParams
from skt_lib.errors import GenerationFailed
from skt_lib.geometry.convex import Mesh, box, hull, prism, rownorm3, sphere, tube

_RING_SEGMENTS = 16


@dataclass(frozen=True, eq=False)
class ObjectShape:
    category: str
    aperture: str  # handle | ring | hole | loop
    parts: tuple[Mesh, ...]


def ring(a_y: float, a_z: float, w: float, square: bool, center=(0.0, 0.0, 0.0)) -> list[Mesh]:
    """A closed loop in the y–z plane (axis +x): ellipse of semi-axes ``a_y``, ``a_z`` on
    its centreline, section half-width ``w``, ``_RING_SEGMENTS`` convex segments."""
    th = 2 * np.pi * np.arange(_RING_SEGMENTS + 1) / _RING_SEGMENTS
    pts = np.stack([np.zeros_like(th), a_y * np.cos(th), a_z * np.sin(th)], 1) + center
    return tube(pts, w, square, side=(1.0, 0.0, 0.0))


def _ring_for_clearance(clearance: float, w: float, aspect: float) -> tuple[float, float]:
    """Centreline semi-axes whose polygonal ring leaves at least ``clearance`` free."""
    a = (clearance + w) / math.cos(math.pi / _RING_SEGMENTS) + 1e-4
    return a, a * aspect


def aperture_clearance(parts: tuple[Mesh, ...] | list[Mesh]) -> float:
    """Radius of the largest rod along the x axis (through the origin) that touches no part.

    Exact for convex parts: the distance from the origin to each part's projection on y–z.
    """
    best = math.inf
    for part in parts:
        yz = part.vertices[:, 1:]
        h = ConvexHull(yz)
        if (h.equations[:, 2] <= 0).all():  # origin inside the projected polygon (n·0 + d <= 0)
            return 0.0
        poly = yz[h.vertices]
        a, b = poly, np.roll(poly, -1, axis=0)
        ab = b - a
        t = np.clip(-(a * ab).sum(1) / (ab * ab).sum(1), 0.0, 1.0)
        d = a + t[:, None] * ab
        best = min(best, float(np.sqrt(d[:, 0] * d[:, 0] + d[:, 1] * d[:, 1]).min()))
    return best


def _u(rng, lo, hi) -> float:
    return float(rng.uniform(lo, hi))


def _mug(rng, rod):
    w = _u(rng, 0.004, 0.006)
    a_y, a_z = _ring_for_clearance(rod * _u(rng, 1.3, 2.0), w, _u(rng, 1.0, 1.6))
    radius, height = _u(rng, 0.03, 0.045), _u(rng, 0.07, 0.11)
    body = prism([0.0, -(a_y + radius), -height * _u(rng, 0.05, 0.25)], radius, height / 2)
    return ObjectShape("mug", "handle", (*ring(a_y, a_z, w, rng.random() < 0.2), body))


def _cooking_utensil(rng, rod):
    w = _u(rng, 0.003, 0.005)
    a, _ = _ring_for_clearance(rod * _u(rng, 1.2, 1.8), w, 1.0)
    length = _u(rng, 0.10, 0.18)
    top = -a + 0.5 * w
    handle = box([0, 0, top - length / 2], [_u(rng, 0.003, 0.005), 1.5 * w, length / 2])
    end = top - length
    if rng.random() < 0.5:  # spatula
        half = [0.003, _u(rng, 0.025, 0.04), _u(rng, 0.03, 0.05)]
        head = box([0, 0, end - half[2] + 0.005], half)
    else:  # ladle bowl
        r = _u(rng, 0.03, 0.045)
        head = sphere([0, 0, end - r + 0.005], r)
    return ObjectShape("cooking_utensil", "hole", (*ring(a, a, w, False), handle, head))


def _scissor(rng, rod):
    w = _u(rng, 0.003, 0.0045)
    a_y, a_z = _ring_for_clearance(rod * _u(rng, 1.2, 1.6), w, _u(rng, 1.1, 1.5))
    y2 = -(2 * a_y + 2 * w + _u(rng, 0.002, 0.008))
    blade_len = _u(rng, 0.07, 0.12)
    parts = [*ring(a_y, a_z, w, False), *ring(a_y, a_z, w, False, center=(0.0, y2, 0.0))]
    base_z = -a_z - w
    for dy in (-0.004, 0.004):
        ym = y2 / 2 + dy
        pts = [[sx * 0.002, y, base_z + sz] for sx in (-1, 1) for y in (0.0, y2) for sz in (0, -0.01)]
        pts += [[sx * 0.0015, ym, base_z - blade_len] for sx in (-1, 1)]
        parts.append(hull(np.array(pts), snap_to_grid=True))
    return ObjectShape("scissor", "ring", tuple(parts))


def _tool(rng, rod):
    w = _u(rng, 0.004, 0.006)
    a, _ = _ring_for_clearance(rod * _u(rng, 1.2, 1.7), w, 1.0)
    length, half_w = _u(rng, 0.08, 0.15), _u(rng, 0.008, 0.012)
    top = -a + 0.5 * w
    handle = box([0, 0, top - length / 2], [0.005, half_w, length / 2])
    end = top - length
    head = box([0, 0, end - 0.01], [0.006, _u(rng, 0.018, 0.025), 0.012])
    jaws = [box([0, y, end - 0.03], [0.006, 0.005, 0.012]) for y in (-0.014, 0.014)]
    return ObjectShape("tool", "hole", (*ring(a, a, w, True), handle, head, *jaws))


def _other(rng, rod):
    w = _u(rng, 0.003, 0.005)
    a, b = _ring_for_clearance(rod * _u(rng, 1.3, 2.2), w, _u(rng, 1.0, 1.4))
    neck_len = _u(rng, 0.01, 0.03)
    top = -b + 0.5 * w
    neck = box([0, 0, top - neck_len / 2], [0.004, 0.006, neck_len / 2])
    radii = np.array([_u(rng, 0.015, 0.04), _u(rng, 0.02, 0.05), _u(rng, 0.02, 0.05)])
    dirs = rng.normal(size=(16, 3))
    dirs /= rownorm3(dirs)[:, None]
    center = np.array([0.0, 0.0, top - neck_len - radii[2] + 0.004])
    body = hull(center + dirs * radii, snap_to_grid=True)
    return ObjectShape("other", "loop", (*ring(a, b, w, False), neck, body))


CATEGORIES: dict[str, Callable] = {
    "mug": _mug,
    "cooking_utensil": _cooking_utensil,
    "scissor": _scissor,
    "tool": _tool,
    "other": _other,
}


def sample_object(rng: np.random.Generator, category: str, p: MeshGenParams, max_tries: int = 50):
    """Draw an object of ``category`` whose aperture admits ``p.object_rod_radius_m``."""
    if category not in CATEGORIES:
        raise ValueError(f"category: unknown {category!r}; expected one of {sorted(CATEGORIES)}")
    for _ in range(max_tries):
        shape = CATEGORIES[category](rng, p.object_rod_radius_m)
        if aperture_clearance(shape.parts) >= p.object_rod_radius_m:
            return shape
    raise GenerationFailed(f"{category}: aperture never admitted the rod", "aperture_too_small")


#: The one reference object that collects SKTs for every support: a round ring of
#: centreline radius 26 mm, section radius 4 mm, with a small weight below so it hangs
#: plumb. Fixed geometry, independent of the seed.
REFERENCE_RING_RADIUS_M = 0.026
REFERENCE_SECTION_M = 0.004


def reference_object() -> ObjectShape:
    a, w = REFERENCE_RING_RADIUS_M, REFERENCE_SECTION_M
    weight = box([0.0, 0.0, -(a + 0.015)], [0.006, 0.012, 0.012])
    return ObjectShape("reference", "ring", (*ring(a, a, w, False), weight))
