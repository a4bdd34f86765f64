"""Convex parts and their union.

Every shape in this project is a union of convex parts. The parts are the collision
geometry (a PyBullet compound shape); their exact boolean union (manifold3d) is the
watertight visual mesh. Vertices: ``(K, 3) float64``, metres, in the shape's own frame.
"""

from dataclasses import dataclass
from functools import lru_cache

import manifold3d as m3
import numpy as np
import trimesh
from scipy.spatial import ConvexHull

from skt_lib.errors import MeshError


@dataclass(frozen=True, eq=False)
class Mesh:
    """A triangle mesh: ``vertices (V, 3) float64`` metres, ``faces (F, 3) int64``
    counter-clockwise seen from outside."""

    vertices: np.ndarray
    faces: np.ndarray

    @property
    def volume(self) -> float:
        v = self.vertices[self.faces]
        return float(np.einsum("ij,ij->i", v[:, 0], np.cross(v[:, 1], v[:, 2])).sum() / 6.0)

    def to_trimesh(self) -> trimesh.Trimesh:
        return trimesh.Trimesh(self.vertices, self.faces, process=False)


def _as_mesh(man: m3.Manifold) -> Mesh:
    if man.status() != m3.Error.NoError:
        raise MeshError(f"manifold operation failed: {man.status()}")
    out = man.to_mesh64()
    verts = np.ascontiguousarray(np.asarray(out.vert_properties)[:, :3], dtype=np.float64)
    return Mesh(verts, np.asarray(out.tri_verts).astype(np.int64))


def _to_manifold(mesh: Mesh) -> m3.Manifold:
    return m3.Manifold(
        m3.Mesh64(
            vert_properties=np.array(mesh.vertices, dtype=np.float64, order="C"),
            tri_verts=np.array(mesh.faces, dtype=np.uint64, order="C"),
        )
    )


@lru_cache(maxsize=4)
def _unit_sphere(subdivisions: int) -> np.ndarray:
    return np.asarray(trimesh.creation.icosphere(subdivisions=subdivisions).vertices)


def hull(points: np.ndarray) -> Mesh:
    """Convex hull of ``points (K, 3)`` as a closed mesh (Qhull), faces wound outward."""
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3 or len(points) < 4:
        raise ValueError(f"points: expected (K>=4, 3), got {points.shape}")
    if not np.isfinite(points).all():
        raise ValueError("points: not finite")
    h = ConvexHull(points)
    used = np.sort(h.vertices)
    remap = np.full(len(points), -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    faces = remap[h.simplices]
    verts = points[used]
    v = verts[faces]
    wrong = np.einsum("ij,ij->i", np.cross(v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]), h.equations[:, :3]) < 0
    faces[wrong] = faces[wrong][:, ::-1]
    return Mesh(verts, faces)


def capsule(p0: np.ndarray, p1: np.ndarray, radius: float, subdivisions: int = 1) -> Mesh:
    """Round segment: hull of two icospheres of ``radius`` at ``p0`` and ``p1``."""
    s = radius * _unit_sphere(subdivisions)
    return hull(np.vstack([np.asarray(p0) + s, np.asarray(p1) + s]))


def sphere(center: np.ndarray, radius: float, subdivisions: int = 2) -> Mesh:
    return hull(np.asarray(center) + radius * _unit_sphere(subdivisions))


def square_segment(p0: np.ndarray, p1: np.ndarray, half: float, side: np.ndarray) -> Mesh:
    """Square-section segment of half-width ``half`` from ``p0`` to ``p1``, extended by
    ``half`` past both ends so consecutive segments cover their joint; one pair of faces
    is normal to ``side`` (a unit vector not parallel to the segment)."""
    p0, p1, side = (np.asarray(a, dtype=np.float64) for a in (p0, p1, side))
    t = p1 - p0
    length = np.linalg.norm(t)
    if length <= 0:
        raise ValueError("square_segment: p0 and p1 coincide")
    t = t / length
    b = side - np.dot(side, t) * t
    b = b / np.linalg.norm(b)
    n = np.cross(t, b)
    corners = [
        p + half * (sb * b + sn * n)
        for p in (p0 - half * t, p1 + half * t)
        for sb in (-1, 1)
        for sn in (-1, 1)
    ]
    return hull(np.array(corners))


def box(center: np.ndarray, half_extents: np.ndarray) -> Mesh:
    """Axis-aligned box."""
    c, h = np.asarray(center, float), np.asarray(half_extents, float)
    signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
    return hull(c + signs * h)


def prism(center: np.ndarray, radius: float, half_height: float, n_sides: int = 24) -> Mesh:
    """Upright (along z) regular prism approximating a cylinder."""
    ang = 2 * np.pi * np.arange(n_sides) / n_sides
    ring = np.stack([radius * np.cos(ang), radius * np.sin(ang), np.zeros(n_sides)], 1)
    c = np.asarray(center, float)
    return hull(np.vstack([c + ring - [0, 0, half_height], c + ring + [0, 0, half_height]]))


def tube(points: np.ndarray, radius: float, square: bool, side=(0.0, 1.0, 0.0)) -> list[Mesh]:
    """Convex parts along a polyline ``points (M, 3)``: one part per segment."""
    points = np.asarray(points, dtype=np.float64)
    if square:
        return [square_segment(a, b, radius, np.asarray(side)) for a, b in zip(points[:-1], points[1:])]
    return [capsule(a, b, radius) for a, b in zip(points[:-1], points[1:])]


def union(parts: list[Mesh]) -> Mesh:
    """Exact boolean union of convex parts: a watertight mesh."""
    if not parts:
        raise ValueError("parts: empty")
    return _as_mesh(m3.Manifold.batch_boolean([_to_manifold(p) for p in parts], m3.OpType.Add))


def intersection_volume(a: list[Mesh], b: Mesh) -> float:
    """Volume of (union of ``a``) ∩ ``b``."""
    ua = m3.Manifold.batch_boolean([_to_manifold(p) for p in a], m3.OpType.Add)
    return float(m3.Manifold.batch_boolean([ua, _to_manifold(b)], m3.OpType.Intersect).volume())


def union_volume(parts: list[Mesh]) -> float:
    return float(m3.Manifold.batch_boolean([_to_manifold(p) for p in parts], m3.OpType.Add).volume())
