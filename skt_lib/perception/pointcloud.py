"""Point-cloud operations: farthest-point sampling (fast + naive reference), checks, noise."""

from dataclasses import dataclass

import numpy as np
import open3d as o3d
from scipy.spatial import cKDTree


def check_cloud(points: np.ndarray, name: str = "points") -> np.ndarray:
    """``points`` as ``(N, 3)`` float64; ``ValueError`` naming it if empty, malformed or NaN."""
    a = np.asarray(points)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"{name}: expected (N, 3), got shape {a.shape}")
    if len(a) == 0:
        raise ValueError(f"{name}: empty point cloud")
    if not np.isfinite(a).all():
        raise ValueError(f"{name}: contains NaN or infinite values")
    return a.astype(np.float64)


def farthest_point_sample(points: np.ndarray, n: int) -> np.ndarray:
    """Indices ``(n,)``, ascending, of a farthest-point sample started at index 0.

    Open3D's (legacy, C++) sampler; its output points are mapped back to input indices
    exactly with a KD-tree. The start is the first point in input order — never a labelled
    point — and callers shuffle the sample so point order carries no information."""
    points = check_cloud(points)
    if not 0 < n <= len(points):
        raise ValueError(f"n: need 0 < n <= {len(points)}, got {n}")
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    picked = np.asarray(pcd.farthest_point_down_sample(n).points)
    _, idx = cKDTree(points).query(picked)
    return np.sort(idx)


def farthest_point_sample_naive(points: np.ndarray, n: int) -> np.ndarray:
    """Reference implementation of :func:`farthest_point_sample` (slow, plain numpy)."""
    points = check_cloud(points)
    chosen = [0]
    dist = np.linalg.norm(points - points[0], axis=1)
    for _ in range(n - 1):
        k = int(np.argmax(dist))
        chosen.append(k)
        dist = np.minimum(dist, np.linalg.norm(points - points[k], axis=1))
    return np.array(chosen)


def add_depth_noise(points: np.ndarray, rays: np.ndarray, std: float, rng) -> np.ndarray:
    """Gaussian noise of ``std`` metres along each point's viewing ray (a depth-sensor model)."""
    if std <= 0:
        return points
    return points + rays * rng.normal(0.0, std, size=(len(points), 1))


def sample_to(points: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """``(n, 3)``: a farthest-point sample of ``points (K, 3)`` when ``K >= n``, else the points
    padded with duplicates drawn by ``rng``; then shuffled by ``rng`` (FPS keeps input order, so
    order would carry information). Every cloud the network sees — training views and clouds
    brought to ``skt predict`` — ends with this."""
    if len(points) >= n:
        chosen = points[farthest_point_sample(points, n)]
    else:
        extra = rng.choice(len(points), n - len(points))
        chosen = np.vstack([points, points[extra]])
    return chosen[rng.permutation(n)]


#: A cloud whose median distance from its median point exceeds this (metres) is taken to be
#: in millimetres: a hook seen by a camera is centimetres across.
MM_MEDIAN_RADIUS_M = 1.0


@dataclass(frozen=True)
class CleanSettings:
    """How a user's cloud is cleaned (:func:`clean_cloud`). Lengths in metres."""

    dense_points: int = 20000  # above this many points, voxel-downsample
    voxel_m: float = 0.002  # voxel edge of that downsampling
    sor_neighbours: int = 20  # statistical outlier removal: neighbours per point
    sor_std_ratio: float = 2.5  # ... and the kept band, in standard deviations
    dbscan_spacing: float = 4.0  # DBSCAN eps = this × the median nearest-neighbour spacing
    dbscan_min_points: int = 5
    min_cluster_share: float = 0.05  # clusters smaller than this share of the points are noise
    structure_reach_m: float = 0.15  # big clusters this near the mount are the structure too
    min_points: int = 100  # fewer points than this left after cleaning: refused


@dataclass(frozen=True)
class CleanedCloud:
    points: np.ndarray  # (K, 3) float64, support frame, metres: the structure's cluster
    counts: dict  # points in, and removed per step: non_finite, voxel, outliers, off_cluster


def median_radius(points: np.ndarray) -> float:
    """Median distance of ``points (N, 3)`` from their median point (robust to < 50 % outliers)."""
    return float(np.median(np.linalg.norm(points - np.median(points, axis=0), axis=1)))


def clean_cloud(points: np.ndarray, s: CleanSettings = CleanSettings(), name: str = "points"
                ) -> CleanedCloud:
    """A depth-camera cloud (``(N, 3)``, support frame, metres) cleaned for the predictor:
    non-finite rows dropped; voxel-downsampled when denser than ``s.dense_points``;
    DBSCAN clusters, keeping the structure — of the clusters holding at least
    ``s.min_cluster_share`` of the points, the one that comes closest to the mounting point
    (the support-frame origin) and every other that comes within ``s.structure_reach_m`` of
    it (a view can see a hook's plate and its arm's far end apart, the middle hidden: keeping
    the nearest alone left the plate and refused 4 of 140 test views, clean or noisy; clutter
    farther out and small clusters — flying pixels — are dropped); statistical outliers
    removed from what is kept. Points are put in
    a canonical (lexicographic) order first, so the result does not depend on input order.
    ``ValueError`` naming ``name`` when too little is left or the cloud is in millimetres."""
    a = np.asarray(points, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"{name}: expected an (N, 3) array of x, y, z, got shape {a.shape}")
    counts = {"n_in": len(a)}
    finite = np.isfinite(a).all(axis=1)
    a = a[finite]
    counts["non_finite"] = int((~finite).sum())
    if len(a) < s.min_points:
        raise ValueError(f"{name}: {len(a)} finite points, need at least {s.min_points}")
    radius = median_radius(a)
    if radius > MM_MEDIAN_RADIUS_M:
        raise ValueError(f"{name}: median radius {radius:.3g} m — a cloud in millimetres? "
                         "clouds must be in metres (pass --units mm to convert)")
    a = a[np.lexsort(a.T[::-1])]  # canonical order: the result does not depend on input order
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(a))
    if len(a) > s.dense_points:
        pcd = pcd.voxel_down_sample(s.voxel_m)
    counts["voxel"] = len(a) - len(pcd.points)
    a = np.asarray(pcd.points)
    spacing, _ = cKDTree(a).query(a, k=2)
    eps = s.dbscan_spacing * float(np.median(spacing[:, 1]))
    labels = np.asarray(pcd.cluster_dbscan(eps, s.dbscan_min_points))
    ids, sizes = np.unique(labels[labels >= 0], return_counts=True)
    big = ids[sizes >= s.min_cluster_share * len(a)]
    if len(big) == 0:
        raise ValueError(f"{name}: no cluster of points (DBSCAN, eps {1000 * eps:.1f} mm): "
                         "is it a point cloud of one object?")
    dist = np.linalg.norm(a, axis=1)
    near = {int(c): float(dist[labels == c].min()) for c in big}
    nearest = min(near, key=lambda c: (near[c], c))
    keep = [c for c in near if c == nearest or near[c] <= s.structure_reach_m]
    kept = a[np.isin(labels, keep)]
    counts["off_cluster"] = len(a) - len(kept)
    cluster = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(kept))
    cluster, _ = cluster.remove_statistical_outlier(s.sor_neighbours, s.sor_std_ratio)
    counts["outliers"] = len(kept) - len(cluster.points)
    kept = np.asarray(cluster.points)
    if len(kept) < s.min_points:
        raise ValueError(f"{name}: {len(kept)} points left on the structure after cleaning, "
                         f"need at least {s.min_points}")
    return CleanedCloud(kept, counts)
