"""Point-cloud operations: farthest-point sampling (fast + naive reference), checks, noise."""

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
