"""The re-check of planned SKTs, independent of the planner's PyBullet probe
(:mod:`skt_lib.planning.probe`).

- :class:`MeshClearance` — exact signed distances
  (Open3D ``RaycastingScene``) of dense surface samples of each watertight mesh to the other
  mesh, plus the wall plane x = 0. Both directions are checked, so a thin arm piercing a
  ring tube is caught even where no vertex lies inside.
"""

import numpy as np
import open3d as o3d
import trimesh
from scipy.spatial import cKDTree

from skt_lib.geometry.convex import Mesh


def _scene(mesh: Mesh) -> o3d.t.geometry.RaycastingScene:
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(mesh.vertices.astype(np.float32)),
                        o3d.core.Tensor(mesh.faces.astype(np.uint32)))
    return scene


def surface_samples(mesh: Mesh, spacing: float) -> np.ndarray:
    """Vertices plus even surface samples about ``spacing`` apart, ``(K, 3)`` float64.

    Deterministic: trimesh's even sampling with a fixed seed."""
    tm = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
    n = int(np.ceil(tm.area / spacing**2))
    pts, _ = trimesh.sample.sample_surface_even(tm, n, seed=0)
    return np.vstack([mesh.vertices, pts])


class MeshClearance:
    """Signed clearance between an object mesh at a pose and a fixed support mesh (+ wall)."""

    def __init__(self, support: Mesh, obj: Mesh, spacing: float = 0.002):
        self._obj_pts = surface_samples(obj, spacing)
        self._sup_pts = surface_samples(support, spacing)
        self._support = _Exact(_scene(support), cKDTree(self._sup_pts), spacing)
        self._object = _Exact(_scene(obj), cKDTree(self._obj_pts), spacing)
        self._obj_radius = float(np.linalg.norm(obj.vertices, axis=1).max())

    def clearance(self, poses: np.ndarray, chunk: int = 128) -> float:
        """Minimum signed distance (m) over all ``poses (N, 4, 4)``, both sample sets and the
        wall plane, capped at 6 mm (farther is reported as 6 mm); < 0 means a collision.
        Poses are taken ``chunk`` at a time (memory stays bounded on long sweeps)."""
        poses = np.asarray(poses).reshape(-1, 4, 4)
        best = np.inf
        for lo in range(0, len(poses), chunk):
            part = poses[lo:lo + chunk]
            obj = np.einsum("nij,kj->nki", part[:, :3, :3], self._obj_pts) + part[:, None, :3, 3]
            obj = obj.reshape(-1, 3)
            best = min(best, float(obj[:, 0].min()), self._support.signed_min(obj))
            near = self._support.samples.query_ball_point(part[:, :3, 3], self._obj_radius + 0.005)
            counts = np.fromiter((len(k) for k in near), int, len(near))
            if counts.sum():
                n_idx = np.repeat(np.arange(len(part)), counts)
                k_idx = np.concatenate([np.asarray(k, int) for k in near])
                inv_r = np.transpose(part[n_idx, :3, :3], (0, 2, 1))
                local = np.einsum("nij,nj->ni", inv_r, self._sup_pts[k_idx] - part[n_idx, :3, 3])
                best = min(best, self._object.signed_min(local))
        return best


class _Exact:
    """Signed distance to one closed mesh, computed exactly only where it can matter."""

    def __init__(self, scene, samples: cKDTree, spacing: float, shell: float = 0.006):
        self.scene, self.samples, self.spacing, self.shell = scene, samples, spacing, shell

    def signed_min(self, points: np.ndarray) -> float:
        """Smallest signed distance of ``points`` to the mesh (negative inside).

        Points farther than ``shell + spacing`` from every surface sample are farther than
        ``shell`` from the surface and, as every part of a penetrating body that crosses the
        surface has samples that close to it, cannot hide a collision: they only bound the
        result from below. The rest get an exact distance and a ray-parity inside test."""
        reach = self.shell + self.spacing
        lo, hi = self.samples.mins - reach, self.samples.maxes + reach
        boxed = np.flatnonzero(np.all((points >= lo) & (points <= hi), axis=1))  # cheap pre-filter
        if not len(boxed):
            return self.shell
        near, _ = self.samples.query(points[boxed], distance_upper_bound=reach)
        close = boxed[np.isfinite(near)]
        if not len(close):
            return self.shell
        pts = o3d.core.Tensor(points[close].astype(np.float32))
        d = self.scene.compute_distance(pts).numpy()
        inside = self.scene.compute_occupancy(pts, nsamples=3).numpy() > 0.5  # ray majority vote
        return float(min(np.where(inside, -d, d).min(), self.shell))
