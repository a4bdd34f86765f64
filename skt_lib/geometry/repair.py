"""Meshes from outside (OBJ, STL, PLY, GLB…): read, check units, repair, simplify.

A user's mesh is repaired where that is safe — duplicate vertices merged (equal ones
everywhere; ones within :data:`WELD_M` only where the surface is open, so a closed solid
whose surface passes within that of itself stays as the file gives it), faces that
collapsed onto an edge or a point (a repeated vertex) dropped, winding made consistent and
outward, small open boundary loops capped, overlapping bodies united — and refused with
the reason otherwise. Faces of zero area whose three vertices are distinct are kept: in a
dense export they are part of a closed surface (dropping them opened holes whose loops
touch, and a watertight 280k-face hook was refused as non-manifold). Above a face budget
the repaired mesh is simplified (:mod:`skt_lib.geometry.simplify`). Collision geometry
comes from :mod:`skt_lib.geometry.decompose`.
"""

import numpy as np
import trimesh
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from skt_lib.errors import MeshError
from skt_lib.geometry.checks import DIAGONAL_RANGE_M, check_solid
from skt_lib.geometry.convex import Mesh, union
from skt_lib.geometry.simplify import Simplified, simplify_to_budget

UNITS = {"m": 1.0, "mm": 0.001}
#: Vertices closer than this (m) are one vertex (:func:`weld`).
WELD_M = 1e-7
#: Open boundary loops up to this many edges are capped; longer ones are real holes.
MAX_CAP_EDGES = 64


def read_mesh(path, units: str = "m") -> Mesh:
    """The mesh in ``path`` (any format trimesh reads; scenes are merged), scaled to metres."""
    try:
        tm = trimesh.load(str(path), force="mesh", process=False)
    except Exception as err:  # trimesh raises many kinds for files it cannot parse
        raise MeshError(f"{path}: not a mesh trimesh can read ({type(err).__name__}: "
                        f"{str(err).splitlines()[0][:120] if str(err) else ''})") from None
    if not isinstance(tm, trimesh.Trimesh) or len(tm.faces) == 0:
        raise MeshError(f"{path}: no triangles in it (not a surface mesh)")
    v = np.asarray(tm.vertices, dtype=np.float64) * UNITS[units]
    if not np.isfinite(v).all():
        raise MeshError(f"{path}: non-finite vertex coordinates")
    diag = float(np.linalg.norm(np.ptp(v, axis=0)))
    lo, hi = DIAGONAL_RANGE_M
    if diag > hi:
        raise MeshError(f"{path}: {diag:.4g} m across — a mesh in millimetres? "
                        "(pass --units mm to convert)")
    if diag < lo:
        raise MeshError(f"{path}: {diag:.4g} m across, below {lo} m"
                        + (" (was it in metres already? drop --units mm)" if units == "mm" else ""))
    return Mesh(v, np.asarray(tm.faces, dtype=np.int64))


def _cap_loops(tm: trimesh.Trimesh, name: str) -> trimesh.Trimesh:
    """Close each open boundary loop with a fan around its centroid."""
    edges = tm.edges_sorted
    uniq, count = np.unique(edges, axis=0, return_counts=True)
    open_edges = uniq[count == 1]
    if len(open_edges) == 0:
        return tm
    # directed boundary edges, as they run in their faces
    directed = tm.edges[np.isin(tm.edges_sorted.view([("", edges.dtype)] * 2),
                                open_edges.view([("", edges.dtype)] * 2)).ravel()]
    nxt = {int(a): int(b) for a, b in directed}
    if len(nxt) != len(directed):
        raise MeshError(f"{name}: not watertight — its open boundary passes through a vertex "
                        "more than once (non-manifold), too tangled to cap safely")
    verts, faces = list(tm.vertices), list(tm.faces)
    seen = set()
    for start in list(nxt):
        if start in seen:
            continue
        loop, v = [], start
        while v not in seen:
            seen.add(v)
            loop.append(v)
            if v not in nxt:
                raise MeshError(f"{name}: not watertight — its open boundary does not close "
                                "into loops")
            v = nxt[v]
        if len(loop) > MAX_CAP_EDGES:
            raise MeshError(f"{name}: not watertight — a hole of {len(loop)} edges, too large "
                            "to cap safely")
        c = len(verts)
        verts.append(np.mean(tm.vertices[loop], axis=0))
        # the cap runs opposite to the boundary's direction in its faces
        faces += [[c, loop[(i + 1) % len(loop)], loop[i]] for i in range(len(loop))]
    return trimesh.Trimesh(np.array(verts), np.array(faces), process=False)


def weld(vertices: np.ndarray, faces: np.ndarray, tol: float = WELD_M,
         only: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Vertices closer than ``tol`` (0: equal) made one (by distance, not by rounding: two
    copies of a vertex a float32 rounding apart can fall either side of a rounding
    boundary), then faces left with a repeated vertex dropped; ``only`` (bool per vertex):
    only pairs with at least one of these (an open edge's end may close onto a vertex of
    the closed part, as at a T-junction). Unreferenced vertices stay (harmless)."""
    vertices = np.asarray(vertices, dtype=np.float64)
    parent = np.arange(len(vertices))
    pairs = cKDTree(vertices).query_pairs(tol, output_type="ndarray")
    if only is not None and len(pairs):
        pairs = pairs[only[pairs[:, 0]] | only[pairs[:, 1]]]
    if len(pairs):
        graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])),
                           shape=(len(vertices),) * 2)
        _, parent = connected_components(graph, directed=False)
    first = np.full(parent.max() + 1, len(vertices))
    np.minimum.at(first, parent, np.arange(len(vertices)))
    f = first[parent][np.asarray(faces, dtype=np.int64)]
    keep = (f[:, 0] != f[:, 1]) & (f[:, 1] != f[:, 2]) & (f[:, 0] != f[:, 2])
    return vertices, f[keep]


def _welded(vertices, faces, tol: float, only: np.ndarray | None = None) -> trimesh.Trimesh:
    """:func:`weld`, duplicate faces and unreferenced vertices removed."""
    tm = trimesh.Trimesh(*weld(vertices, faces, tol, only), process=False)
    tm.update_faces(tm.unique_faces())
    tm.remove_unreferenced_vertices()
    return tm


def _on_open_edges(tm: trimesh.Trimesh) -> np.ndarray:
    """Per vertex: whether it ends an edge only one face has (the surface is open there)."""
    uniq, count = np.unique(tm.edges_sorted, axis=0, return_counts=True)
    out = np.zeros(len(tm.vertices), bool)
    out[uniq[count == 1].ravel()] = True
    return out


def repair(mesh: Mesh, name: str) -> Mesh:
    """A closed, consistently wound, outward solid from ``mesh``, or :class:`MeshError`
    saying why not."""
    tm = _welded(mesh.vertices, mesh.faces, 0.0)  # exact copies (an STL's per-face vertices)
    if not tm.is_watertight:  # near copies too, where the surface is open and only there
        tm = _welded(tm.vertices, tm.faces, WELD_M, _on_open_edges(tm))
    if not tm.is_watertight:
        tm = _cap_loops(tm, name)
        tm.merge_vertices()
    if not tm.is_watertight:
        raise MeshError(f"{name}: not watertight and could not be repaired (non-manifold edges)")
    bodies = tm.split(only_watertight=False)
    solids = []
    for b in bodies:
        trimesh.repair.fix_winding(b)
        trimesh.repair.fix_inversion(b)
        if not b.is_winding_consistent:
            raise MeshError(f"{name}: inconsistent face winding that could not be fixed")
        solids.append(Mesh(np.asarray(b.vertices), np.asarray(b.faces, dtype=np.int64)))
    out = union(solids) if len(solids) > 1 else solids[0]
    check_solid(out, name)
    return out


def load_solid(path, units: str = "m") -> Simplified:
    """The mesh in ``path`` read (:func:`read_mesh`), repaired (:func:`repair`) and
    simplified to the face budget (:func:`simplify_to_budget`)."""
    return simplify_to_budget(repair(read_mesh(path, units), str(path)))
