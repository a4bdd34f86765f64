"""Dense meshes made light: simplification to a face budget, and the Hausdorff distance.

CAD exports and scans of a hook often carry 10⁵–10⁶ triangles; every later step (the
convex decomposition, the arm's centreline, the planner's clearance, the renderer) pays
for each. Above :data:`MAX_FACES` the repaired mesh is simplified in two steps:

1. manifold3d's edge collapse at :data:`FLAT_TOL_M` — it removes the triangles that add
   nothing (flat or nearly flat stretches), keeps the mesh a closed manifold and moves no
   surface by more than that tolerance (0.02 mm; 5–20× fewer faces on the test zoo's
   smooth 250k-face meshes);
2. quadric edge collapse (Garland–Heckbert, Open3D) to :data:`MAX_FACES` — the error metric
   keeps the curvature where it is (0.04–0.15 mm Hausdorff on the test zoo's 250k-face
   hooks and mugs at 10k faces). Its result is accepted only if it is a closed, edge- and
   vertex-manifold solid that does not intersect itself; otherwise manifold3d's collapse at
   growing tolerances (:data:`TOLERANCES_M`) is used instead.

The measured two-sided Hausdorff distance between the two surfaces is reported
(:func:`hausdorff`).
"""

from dataclasses import dataclass

import manifold3d as m3
import numpy as np

from skt_lib.errors import MeshError
from skt_lib.geometry.checks import check_solid
from skt_lib.geometry.convex import Mesh, _as_mesh, _to_manifold

#: Face budget: a repaired mesh with more triangles is simplified.
MAX_FACES = 10_000
#: The first step's tolerance (m).
FLAT_TOL_M = 2e-5
#: The fallback's tolerances, tried in turn (m): no surface moves by more than the one used.
TOLERANCES_M = (5e-5, 1e-4, 2e-4, 3e-4, 5e-4)


@dataclass(frozen=True)
class Simplified:
    mesh: Mesh
    faces_before: int
    method: str  # "none": not simplified
    hausdorff_m: float  # measured, two-sided


def simplify_within(mesh: Mesh, tolerance_m: float) -> Mesh:
    """``mesh`` with edges collapsed wherever no surface moves more than ``tolerance_m``."""
    return _as_mesh(_to_manifold(mesh).simplify(tolerance_m))


def _surface_samples(mesh: Mesh, n: int, rng: np.random.Generator) -> np.ndarray:
    tri = mesh.vertices[mesh.faces]
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    k = rng.choice(len(tri), size=n, p=area / area.sum())
    u, v = rng.random(n), rng.random(n)
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    t = tri[k]
    return t[:, 0] + u[:, None] * (t[:, 1] - t[:, 0]) + v[:, None] * (t[:, 2] - t[:, 0])


def _distances(points: np.ndarray, mesh: Mesh) -> np.ndarray:
    import open3d as o3d

    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(mesh.vertices.astype(np.float32)),
                        o3d.core.Tensor(mesh.faces.astype(np.uint32)))
    return scene.compute_distance(o3d.core.Tensor(points.astype(np.float32))).numpy()


def hausdorff(a: Mesh, b: Mesh, n: int = 20_000, seed: int = 0) -> float:
    """Two-sided Hausdorff distance between the surfaces of ``a`` and ``b`` (m), from
    ``n`` area-uniform samples on each (a lower bound that converges as ``n`` grows)."""
    rng = np.random.default_rng(seed)
    return float(max(_distances(_surface_samples(a, n, rng), b).max(),
                     _distances(_surface_samples(b, n, rng), a).max()))


def _quadric(mesh: Mesh, max_faces: int) -> Mesh | None:
    """Quadric edge collapse to ``max_faces``, or None when the result is not a closed,
    manifold, self-intersection-free solid."""
    import open3d as o3d

    om = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(np.array(mesh.vertices)),
                                   o3d.utility.Vector3iVector(np.array(mesh.faces)))
    out = om.simplify_quadric_decimation(max_faces)
    if not (out.is_edge_manifold() and out.is_vertex_manifold() and out.is_watertight()
            and not out.is_self_intersecting()):
        return None
    result = Mesh(np.asarray(out.vertices), np.asarray(out.triangles).astype(np.int64))
    try:
        check_solid(result, "simplified mesh")
    except MeshError:
        return None
    return result


def _ladder(mesh: Mesh, max_faces: int) -> tuple[Mesh, float]:
    """manifold3d's collapse at growing tolerances until ``max_faces`` (or the last)."""
    man, out, tol = _to_manifold(mesh), mesh, 0.0
    for tol in TOLERANCES_M:
        simplified = man.simplify(tol)
        if simplified.status() != m3.Error.NoError or simplified.num_tri() == 0:
            break
        out = _as_mesh(simplified)
        if len(out.faces) <= max_faces:
            break
    return out, tol


def simplify_to_budget(mesh: Mesh, max_faces: int = MAX_FACES) -> Simplified:
    """``mesh`` simplified until it has at most ``max_faces`` triangles (see the module
    docstring); unchanged when it already has."""
    n = len(mesh.faces)
    if n <= max_faces:
        return Simplified(mesh, n, "none", 0.0)
    flat = simplify_within(mesh, FLAT_TOL_M)
    if len(flat.faces) <= max_faces:
        return Simplified(flat, n, f"manifold collapse at {1e3 * FLAT_TOL_M:g} mm",
                          hausdorff(mesh, flat))
    out = _quadric(flat, max_faces)
    if out is not None:
        return Simplified(out, n, "quadric collapse", hausdorff(mesh, out))
    out, tol = _ladder(flat, max_faces)
    return Simplified(out, n, f"manifold collapse at {1e3 * tol:g} mm", hausdorff(mesh, out))
