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
        obj_pts = surface_samples(obj, spacing)
        sup_pts = surface_samples(support, spacing)
        self._support = _Exact(_scene(support), cKDTree(sup_pts), spacing)
        self._object = _Exact(_scene(obj), cKDTree(obj_pts), spacing)
        self._obj_radius = float(np.linalg.norm(obj.vertices, axis=1).max())
        self._obj_cells, self._sup_cells = _Cells(obj_pts, CELL_M), _Cells(sup_pts, CELL_M)

    def clearance(self, poses: np.ndarray, chunk: int = 128, max_step_m: float | None = None) -> float:
        """Minimum signed distance (m) over all ``poses (N, 4, 4)``, both sample sets and the
        wall plane, capped at 6 mm (farther is reported as 6 mm); < 0 means a collision.
        Poses are taken ``chunk`` at a time (memory stays bounded on long sweeps).

        Only samples of cells (:class:`_Cells`) that can come within reach are moved: the
        result is exactly that of moving every sample (:meth:`clearance_naive`;
        ``tests/planning/test_collision.py`` holds the two equal, bit for bit, pose by pose).

        ``max_step_m``: a bound on how far any point of the object moves between consecutive
        poses (``executed_path``'s step). The clearance is then found without evaluating
        every pose, and is still exactly the minimum over all of them: every term is a
        distance of a moved point (or to the moved mesh), so a pose that its neighbour's
        points move at most ``m`` from has at least that neighbour's value − ``m``. Each step
        is bounded by the smaller of ``max_step_m`` and what the poses themselves give
        (:meth:`step_bounds`). Every :data:`STRIDE`-th pose is evaluated, then the pose
        halfway between two evaluated ones whose bound could fall below the smallest value
        found (:data:`BOUND_SLACK_M` of slack for float32 distances), and so on, halving.
        The bound is taken on the values capped at :data:`REVERSE_MARGIN_M`: support samples
        beyond the object's reach + that margin are not evaluated, so only below it is each
        pose's value the minimum of distances (which move no faster than the points)."""
        poses = np.asarray(poses).reshape(-1, 4, 4)
        if max_step_m is None or len(poses) <= 2 * STRIDE:
            return float(self.per_pose(poses, chunk).min(initial=self._support.shell))
        moved = np.r_[0.0, np.cumsum(np.minimum(self.step_bounds(poses), max_step_m))]
        capped = np.empty(len(poses))
        best = np.inf
        todo = np.unique(np.r_[np.arange(0, len(poses), STRIDE), len(poses) - 1])
        a, b = todo[:-1], todo[1:]
        while len(todo):
            v = self.per_pose(poses[todo], chunk)
            best, capped[todo] = min(best, float(v.min())), np.minimum(v, REVERSE_MARGIN_M)
            open_ = b > a + 1
            a, b = a[open_], b[open_]
            lower = (capped[a] + capped[b] - (moved[b] - moved[a])) / 2  # the least any pose between can have
            refine = lower <= best + BOUND_SLACK_M
            a, b = a[refine], b[refine]
            todo = (a + b) // 2
            a, b = np.r_[a, todo], np.r_[todo, b]
        return best

    def step_bounds(self, poses: np.ndarray) -> np.ndarray:
        """``(N − 1,)``: how far any object sample moves at most from each pose to the next —
        the frame's shift plus the chord its rotation sweeps at the object's radius
        (``2 sin(θ/2) r``), with :data:`STEP_SLACK_M` for rounding."""
        shift = np.linalg.norm(np.diff(poses[:, :3, 3], axis=0), axis=1)
        trace = np.einsum("nij,nij->n", poses[:-1, :3, :3], poses[1:, :3, :3])  # tr(Ra^T Rb)
        chord = np.sqrt(np.maximum(3.0 - trace, 0.0))  # 2 sin(θ/2), θ the relative rotation
        return shift + chord * self._obj_radius + STEP_SLACK_M

    def per_pose(self, poses: np.ndarray, chunk: int = 128) -> np.ndarray:
        """:meth:`clearance` of each of ``poses (N, 4, 4)`` on its own, ``(N,)``."""
        poses = np.asarray(poses).reshape(-1, 4, 4)
        shell, reach = self._support.shell, self._support.shell + self._support.spacing
        out = np.full(len(poses), shell)
        for lo in range(0, len(poses), chunk):
            part = poses[lo:lo + chunk]
            best = out[lo:lo + chunk]  # a view: filled in place
            rot, shift = part[:, :3, :3], part[:, None, :3, 3]
            # object samples (moved) against the support and the wall plane x = 0
            moved = np.einsum("nij,kj->nki", rot, self._obj_cells.centres) + shift
            d = self._obj_cells.distance(moved, self._support.samples, reach)
            keep = (d <= reach) | (moved[..., 0] - self._obj_cells.radii <= shell)
            n, k = self._obj_cells.members(keep)
            obj = np.einsum("nij,nj->ni", rot[n], self._obj_cells.points[k]) + part[n, :3, 3]
            np.minimum.at(best, n, obj[:, 0])
            np.minimum.at(best, n, self._support.signed(obj))
            # support samples within the object's reach (+ 5 mm), in the object frame
            inv_r = np.transpose(rot, (0, 2, 1))
            local = np.einsum("nij,nkj->nki", inv_r, self._sup_cells.centres[None] - shift)
            d = self._sup_cells.distance(local, self._object.samples, reach)
            ball = self._obj_radius + REVERSE_MARGIN_M
            off = (np.linalg.norm(self._sup_cells.centres[None] - shift, axis=2)
                   - self._sup_cells.radii)
            n, k = self._sup_cells.members((d <= reach) & (off <= ball))
            rel = self._sup_cells.points[k] - part[n, :3, 3]
            inside = np.einsum("ni,ni->n", rel, rel) <= ball * ball  # the ball of the full check
            n, rel = n[inside], rel[inside]
            if len(n):
                local = np.einsum("nij,nj->ni", inv_r[n], rel)
                np.minimum.at(best, n, self._object.signed(local))
        return out

    def clearance_naive(self, poses: np.ndarray) -> float:
        """:meth:`clearance` moving every sample of both meshes (the reference it equals)."""
        poses = np.asarray(poses).reshape(-1, 4, 4)
        shell = self._support.shell
        obj = (np.einsum("nij,kj->nki", poses[:, :3, :3], self._obj_cells.points)
               + poses[:, None, :3, 3]).reshape(-1, 3)
        best = min(shell, float(obj[:, 0].min()), self._support.signed_min(obj))
        ball = self._obj_radius + REVERSE_MARGIN_M
        for pose in poses:
            rel = self._sup_cells.points - pose[:3, 3]
            rel = rel[np.einsum("ni,ni->n", rel, rel) <= ball * ball]
            if len(rel):
                best = min(best, self._object.signed_min(rel @ pose[:3, :3]))
        return best


#: :meth:`MeshClearance.clearance` with a step bound evaluates every STRIDE-th pose first.
STRIDE = 4
#: Support samples farther than the object's radius + this from its frame are not checked
#: against it (they are farther than this from every object point).
REVERSE_MARGIN_M = 0.005
#: Slack (m) on the Lipschitz bound of the refinement: Open3D's distances are float32.
BOUND_SLACK_M = 1e-5
#: Added to each step bound (m): the rotation's chord is found from a trace near 3, whose
#: rounding (~1e-15) gives at most ~3e-8 of chord, times a radius under a metre.
STEP_SLACK_M = 1e-7
#: Edge of the cells (m) samples are grouped in, so that whole cells out of reach are skipped
#: before any of their samples is moved (:class:`_Cells`).
CELL_M = 0.01
#: Added to each cell's radius so that rounding never skips a cell that matters (m).
SLACK_M = 1e-6


class _Cells:
    """Surface samples grouped in cubic cells, each with its centre and radius (+ slack).

    A cell whose moved centre lies farther than its radius + ``reach`` from every sample of
    the other mesh holds no sample within ``reach`` of it, so the exact check
    (:meth:`_Exact.signed_min`) would have skipped each of them anyway."""

    def __init__(self, points: np.ndarray, cell: float):
        _, group = np.unique(np.floor(points / cell).astype(np.int64), axis=0, return_inverse=True)
        group = group.ravel()
        order = np.argsort(group, kind="stable")
        self.points = points[order]
        self.starts = np.searchsorted(group[order], np.arange(group.max() + 2))
        sizes = np.diff(self.starts)
        self.centres = np.add.reduceat(self.points, self.starts[:-1]) / sizes[:, None]
        spread = np.linalg.norm(self.points - np.repeat(self.centres, sizes, axis=0), axis=1)
        self.radii = np.maximum.reduceat(spread, self.starts[:-1]) + SLACK_M

    def distance(self, centres: np.ndarray, other: cKDTree, reach: float) -> np.ndarray:
        """``(N, G)``: distance of each moved centre ``(N, G, 3)`` to ``other``'s nearest
        sample, less the cell's radius (``inf`` beyond ``reach``)."""
        d, _ = other.query(centres.reshape(-1, 3),
                           distance_upper_bound=float(self.radii.max()) + reach)
        return d.reshape(centres.shape[:2]) - self.radii

    def members(self, keep: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(pose index, sample index) of every sample of every kept ``(N, G)`` cell."""
        n, g = np.divmod(np.flatnonzero(keep), keep.shape[1])
        sizes = self.starts[g + 1] - self.starts[g]
        first = np.repeat(self.starts[g] - (np.cumsum(sizes) - sizes), sizes)
        return np.repeat(n, sizes), first + np.arange(int(sizes.sum()))


class _Exact:
    """Signed distance to one closed mesh, computed exactly only where it can matter."""

    def __init__(self, scene, samples: cKDTree, spacing: float, shell: float = 0.006):
        self.scene, self.samples, self.spacing, self.shell = scene, samples, spacing, shell

    def signed(self, points: np.ndarray) -> np.ndarray:
        """Signed distance of each of ``points`` to the mesh (negative inside), capped at
        ``shell``: points farther than ``shell + spacing`` from every surface sample are
        farther than ``shell`` from the surface and, as every part of a penetrating body that
        crosses the surface has samples that close to it, cannot hide a collision: they get
        ``shell``. The rest get an exact distance and a ray-parity inside test."""
        out = np.full(len(points), self.shell)
        reach = self.shell + self.spacing
        lo, hi = self.samples.mins - reach, self.samples.maxes + reach
        boxed = np.flatnonzero(np.all((points >= lo) & (points <= hi), axis=1))  # cheap pre-filter
        if not len(boxed):
            return out
        near, _ = self.samples.query(points[boxed], distance_upper_bound=reach)
        close = boxed[np.isfinite(near)]
        if not len(close):
            return out
        pts = o3d.core.Tensor(points[close].astype(np.float32))
        d = self.scene.compute_distance(pts).numpy()
        inside = self.scene.compute_occupancy(pts, nsamples=3).numpy() > 0.5  # ray majority vote
        out[close] = np.minimum(np.where(inside, -d, d), self.shell)
        return out

    def signed_min(self, points: np.ndarray) -> float:
        """Smallest of :meth:`signed` (``shell`` for no point)."""
        return float(self.signed(points).min(initial=self.shell))
