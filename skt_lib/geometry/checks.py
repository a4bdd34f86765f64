"""Mesh checks: watertightness, volume, units, convexity, part coverage."""

import numpy as np
import trimesh

from skt_lib.errors import MeshError
from skt_lib.geometry.convex import Mesh, hull, intersection_volume, union_volume

#: A shape whose bounding-box diagonal is outside this range (metres) is rejected: below it
#: is dust, above it is almost certainly a mesh in millimetres.
DIAGONAL_RANGE_M = (0.005, 2.0)


def check_solid(mesh: Mesh, name: str) -> None:
    """Raise :class:`MeshError` unless ``mesh`` is a closed, consistently wound solid of
    positive volume and plausible size in metres."""
    if len(mesh.faces) == 0 or not np.isfinite(mesh.vertices).all():
        raise MeshError(f"{name}: empty mesh or non-finite vertices")
    tm = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
    if not tm.is_watertight:
        raise MeshError(f"{name}: mesh is not watertight")
    if not tm.is_winding_consistent:
        raise MeshError(f"{name}: inconsistent face winding")
    if mesh.volume <= 0:
        raise MeshError(f"{name}: non-positive volume {mesh.volume:.3e} m^3 (inverted faces?)")
    diag = float(np.linalg.norm(np.ptp(mesh.vertices, axis=0)))
    lo, hi = DIAGONAL_RANGE_M
    if not lo <= diag <= hi:
        hint = " (a mesh in millimetres? meshes must be in metres)" if diag > hi else ""
        raise MeshError(f"{name}: bounding-box diagonal {diag:.4g} m is outside [{lo}, {hi}]{hint}")


def convexity_gap(part: Mesh) -> float:
    """Relative volume the part lacks to its convex hull (0 for a convex part)."""
    hv = hull(part.vertices).volume
    return float((hv - part.volume) / hv)


def check_parts(parts: list[Mesh], visual: Mesh, name: str, min_iou: float = 0.95) -> float:
    """Every part a convex solid and the parts' union matching ``visual``; returns the IoU."""
    for k, part in enumerate(parts):
        check_solid(part, f"{name} part {k}")
        gap = convexity_gap(part)
        if gap > 1e-6:
            raise MeshError(f"{name} part {k}: not convex (hull volume exceeds it by {gap:.2e})")
    inter = intersection_volume(parts, visual)
    iou = inter / (union_volume(parts) + visual.volume - inter)
    if iou < min_iou:
        raise MeshError(f"{name}: convex parts cover the visual mesh with IoU {iou:.4f} < {min_iou}")
    return iou
