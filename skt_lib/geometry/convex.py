"""Convex parts and their union.

Every shape in this project is a union of convex parts. The parts are the collision
geometry (a PyBullet compound shape); their exact boolean union (manifold3d) is the
watertight visual mesh. Vertices: ``(K, 3) float64``, metres, in the shape's own frame.

Reproducibility: the bytes ``mesh_gen`` writes must not depend on the CPU. Two things make
them do so unless avoided: numpy hands ``np.dot`` / ``np.linalg.norm`` of a vector / ``@`` to
OpenBLAS, whose kernel (chosen at run time per CPU: Haswell, SkylakeX…) rounds differently
in the last bit; and numpy's SIMD loops for some functions (``np.arccos`` …) differ between
AVX2 and AVX-512. One ulp in a vertex is enough to make Qhull triangulate a flat face the
other way, and manifold3d's union then differs in topology. So the procedural shapes use
only correctly rounded elementwise operations (:func:`dot3`, :func:`norm3`,
:func:`rowdot3`, :func:`rownorm3`, ``math``), and their defining points are snapped to a
:data:`GRID_M` grid (:func:`snap`; ``hull(..., snap_to_grid=True)``) so that last-bit noise
from anything upstream (numpy's SIMD ``np.cos``, trimesh…) is removed before Qhull.
"""

import math
from dataclasses import dataclass
from functools import lru_cache

import manifold3d as m3
import numpy as np
import trimesh
from scipy.spatial import ConvexHull

from skt_lib.errors import MeshError

#: Procedural vertices are snapped to this grid (metres): the precision the OBJ files are
#: written with (``%.9f``), so what is written and read back is exactly what was built.
GRID_M = 1e-9
_PER_M = 1e9  # 1 / GRID_M, exact


def snap(points) -> np.ndarray:
    """``points`` rounded to the :data:`GRID_M` grid: each the double nearest ``k * 1e-9``
    (what ``float("%.9f" % x)`` gives), never ``-0.0``. Correctly rounded elementwise
    operations only, so the same on every CPU."""
    return np.rint(np.asarray(points, dtype=np.float64) * _PER_M) / _PER_M + 0.0


def dot3(a, b) -> float:
    """Dot product of two short vectors, the same on every CPU (no BLAS)."""
    return math.fsum(float(x) * float(y) for x, y in zip(a, b))


def norm3(a) -> float:
    """Euclidean norm of a short vector, the same on every CPU (no BLAS)."""
    return math.sqrt(dot3(a, a))


def rowdot3(rows: np.ndarray, v) -> np.ndarray:
    """``rows (N, 3) @ v (3,)`` in a fixed order, the same on every CPU (no BLAS)."""
    rows = np.asarray(rows, dtype=np.float64)
    return rows[..., 0] * float(v[0]) + rows[..., 1] * float(v[1]) + rows[..., 2] * float(v[2])


def rownorm3(rows: np.ndarray) -> np.ndarray:
    """Norms of the rows of ``rows (N, 3)``, the same on every CPU."""
    rows = np.asarray(rows, dtype=np.float64)
    return np.sqrt(rowdot3(rows * rows, (1.0, 1.0, 1.0)))


@dataclass(frozen=True, eq=False)
class Mesh:
    """A triangle mesh: ``vertices (V, 3) float64`` metres, ``faces (F, 3) int64``
    counter-clockwise seen from outside."""

    vertices: np.ndarray
    faces: np.ndarray

    @property
    def volume(self) -> float:
        v = self.vertices[self.faces]
        # elementwise products and an exactly rounded sum: no einsum (its SIMD loops may fuse
        # multiply-adds on some builds) and no summation order to depend on
        c = np.cross(v[:, 1], v[:, 2])
        triple = v[:, 0, 0] * c[:, 0] + v[:, 0, 1] * c[:, 1] + v[:, 0, 2] * c[:, 2]
        return math.fsum(triple.tolist()) / 6.0

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
    return snap(trimesh.creation.icosphere(subdivisions=subdivisions).vertices)


def hull(points: np.ndarray, snap_to_grid: bool = False) -> Mesh:
    """Convex hull of ``points (K, 3)`` as a closed mesh (Qhull), faces wound outward.
    ``snap_to_grid``: round the points to :data:`GRID_M` first (procedural shapes: makes
    the hull independent of last-bit noise in the points, see the module docstring)."""
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3 or len(points) < 4:
        raise ValueError(f"points: expected (K>=4, 3), got {points.shape}")
    if not np.isfinite(points).all():
        raise ValueError("points: not finite")
    if snap_to_grid:
        points = snap(points)
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
    # the ends are snapped, not the hull's points: the sides stay planar to the last bit
    # (snapping them would crease every side quad and fill the union with slivers)
    s = radius * _unit_sphere(subdivisions)
    return hull(np.vstack([snap(p0) + s, snap(p1) + s]))


def sphere(center: np.ndarray, radius: float, subdivisions: int = 2) -> Mesh:
    return hull(np.asarray(center) + radius * _unit_sphere(subdivisions), snap_to_grid=True)


def square_segment(p0: np.ndarray, p1: np.ndarray, half: float, side: np.ndarray) -> Mesh:
    """Square-section segment of half-width ``half`` from ``p0`` to ``p1``, extended by
    ``half`` past both ends so consecutive segments cover their joint; one pair of faces
    is normal to ``side`` (a unit vector not parallel to the segment)."""
    p0, p1, side = snap(p0), snap(p1), np.asarray(side, dtype=np.float64)  # as in capsule
    t = p1 - p0
    length = norm3(t)
    if length <= 0:
        raise ValueError("square_segment: p0 and p1 coincide")
    t = t / length
    b = side - dot3(side, t) * t
    b = b / norm3(b)
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
    return hull(c + signs * h, snap_to_grid=True)


def prism(center: np.ndarray, radius: float, half_height: float, n_sides: int = 24) -> Mesh:
    """Upright (along z) regular prism approximating a cylinder."""
    ang = 2 * np.pi * np.arange(n_sides) / n_sides
    ring = np.stack([radius * np.cos(ang), radius * np.sin(ang), np.zeros(n_sides)], 1)
    c = np.asarray(center, float)
    return hull(np.vstack([c + ring - [0, 0, half_height], c + ring + [0, 0, half_height]]),
                snap_to_grid=True)


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
