"""The support frame from a raw depth-camera cloud: the wall plane, gravity, and where the
hook meets the wall (``skt predict --camera``).

1. **The wall** is the largest plane of the cloud (RANSAC, seeded and single-threaded so
   that it repeats), refit by least squares to its inliers; its normal, turned toward the camera,
   is the support frame's +x.
2. **Up** is the user's: ``up`` in the camera frame (an IMU's gravity, reversed), or, for a
   camera held level (image rows horizontal), the wall's vertical seen from it. Its part in
   the wall plane is +z; +y = z × x.
3. **The structure** is the off-wall points (more than ``off_wall_m`` in front of the plane)
   clustered (DBSCAN): of the clusters that reach the wall (within ``touch_m``), the largest,
   and every other cluster of ``min_part_points`` or more within ``reach_m`` of it (an arm
   in front of its plate cuts the plate's view in pieces; an arm seen end-on shows only its
   tip).
4. **The mount** — the support frame's origin — is on the plane, centred across the
   structure's footprint on the wall (its points within ``footprint_m`` of the plane: a
   plate, or a bare hook's base; box of the robust 1–99 % quantiles) and ``mount_above_m``
   over the footprint's lower edge, or at its centre when it is lower than twice that. That
   is the generated supports' convention: a plate reaching 2.5 cm past the lowest arm's
   root, the frame at that root (a double hook's sits at its lower arm, not the plate's
   centre).
5. **The check** of that lower edge: the wall must be seen in a band below the footprint
   (``below_gap_m`` under its lower edge, ``below_band_m`` tall, across its width; the gap
   clears the shadow a 1 cm plate casts seen from above). A camera high above a hook sees
   its arm in front of the plate's lower part, and a noisy one loses the plate's face at
   that angle: the footprint then ends too high, and so does the frame, by 1–3 cm, with
   nothing else amiss. Where less than ``min_below_seen`` of the band's ``below_cell_m``
   cells hold a wall point, the frame carries a warning.

What is returned: the camera-to-support transform and the structure's points, wall removed,
in the support frame — what the predictor's training views show — and the check's
warnings.
"""

from dataclasses import dataclass, replace

import numpy as np
import open3d as o3d
from scipy.spatial import cKDTree

from skt_lib.errors import InputError

#: A camera-frame cloud whose median range exceeds this (m) is taken to be in millimetres.
MM_MEDIAN_RANGE_M = 20.0


@dataclass(frozen=True)
class WallSettings:
    voxel_m: float = 0.002  # clouds are voxel-downsampled to this first
    plane_tol_m: float = 0.004  # RANSAC inlier distance
    ransac_iterations: int = 1000
    ransac_points: int = 4000  # inliers are counted on a seeded sample of this many points
    min_wall_share: float = 0.2  # the wall plane must hold this share of the points
    min_up_angle_deg: float = 30.0  # up must be this far from the wall normal
    min_level_angle_deg: float = 10.0  # --level: the camera's x this far from the normal
    off_wall_m: float = 0.004  # nearer the plane than this is wall
    max_reach_m: float = 0.4  # farther in front of the wall than this is not the hook
    cluster_eps_m: float = 0.008  # DBSCAN neighbourhood of the structure's clusters
    cluster_min_points: int = 8
    touch_m: float = 0.015  # a cluster nearer the wall than this reaches it
    reach_m: float = 0.15  # clusters this near the structure's main one are structure too
    min_part_points: int = 30  # ... if they hold this many points (fewer: flying pixels)
    footprint_m: float = 0.015  # the structure's points this near the wall are its footprint
    mount_above_m: float = 0.025  # the mount's height over the footprint's lower edge
    min_structure_points: int = 100
    seed: int = 0  # RANSAC's seed
    noise_k: float = 4.0  # the wall's band is at least this many σ of its depth noise
    below_gap_m: float = 0.015  # the check's band starts this far below the footprint ...
    below_band_m: float = 0.016  # ... and is this tall
    below_cell_m: float = 0.004  # its cells (twice the voxel)
    min_below_seen: float = 0.6  # share of its cells holding a wall point (validation views)


@dataclass(frozen=True, eq=False)
class WallFrame:
    camera_to_support: np.ndarray  # (4, 4)
    points: np.ndarray  # (K, 3) the structure, support frame, wall removed
    n_wall: int  # points on the wall plane (after downsampling)
    n_in: int  # points after downsampling
    #: share of the band below the footprint where the wall is seen (the check, step 5)
    below_seen: float = 1.0
    warnings: tuple[str, ...] = ()  # one line each: why the frame may be off


def _ransac(points: np.ndarray, s: WallSettings) -> np.ndarray:
    """Inlier mask of the plane through three points that most points lie within
    ``plane_tol_m`` of (counted on ``ransac_points`` of them), over ``ransac_iterations``
    seeded draws (the first best on ties).
    Open3D's ``segment_plane`` runs its draws on several threads and is not repeatable."""
    rng = np.random.default_rng(s.seed)
    tri = points[rng.integers(0, len(points), size=(s.ransac_iterations, 3))]
    sample = points[rng.choice(len(points), min(len(points), s.ransac_points), replace=False)]
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    norm = np.linalg.norm(n, axis=1)
    ok = norm > 1e-12
    n[ok] /= norm[ok, None]
    d = -(n * tri[:, 0]).sum(1)
    counts = np.zeros(len(n), int)
    for i in range(0, len(n), 64):  # (64, N) distances at a time
        dist = np.abs(n[i:i + 64] @ sample.T + d[i:i + 64, None])
        counts[i:i + 64] = (dist <= s.plane_tol_m).sum(1)
    best = int(np.argmax(np.where(ok, counts, -1)))
    return np.abs(points @ n[best] + d[best]) <= s.plane_tol_m


def _plane(points: np.ndarray, s: WallSettings) -> tuple[np.ndarray, float, np.ndarray]:
    """(unit normal, offset, inlier mask) of the largest plane, n·p + d = 0, refit."""
    mask = _ransac(points, s)
    n, d = np.array([0.0, 0.0, 1.0]), 0.0
    for _ in range(2):  # least-squares refit to the inliers, then the inliers again
        if mask.sum() < 3:
            break
        c = points[mask].mean(0)
        n = np.linalg.svd(points[mask] - c, full_matrices=False)[2][-1]
        d = -float(n @ c)
        mask = np.abs(points @ n + d) <= s.plane_tol_m
    if d < 0:  # the camera (the origin) on the positive side: n points out of the wall
        n, d = -n, -d
    return n, d, mask


def _up_in_wall(normal: np.ndarray, up: np.ndarray | None, s: WallSettings) -> np.ndarray:
    if up is None:  # a level camera: image rows horizontal, so up ⟂ the camera's x
        z = np.cross(normal, [1.0, 0.0, 0.0])
        if np.linalg.norm(z) < np.sin(np.radians(s.min_level_angle_deg)):
            raise InputError("--level: the wall faces sideways in the image (its normal is "
                             "along the camera's x axis); pass --up instead")
        z = z if z @ [0.0, -1.0, 0.0] > 0 else -z  # image up is the camera's -y
        return z / np.linalg.norm(z)
    up = np.asarray(up, float)
    if up.shape != (3,) or not np.isfinite(up).all() or np.linalg.norm(up) == 0:
        raise InputError(f"--up: expected three finite numbers, not all zero, got {up.tolist()}")
    up = up / np.linalg.norm(up)
    angle = np.degrees(np.arccos(min(1.0, abs(float(up @ normal)))))
    if angle < s.min_up_angle_deg:
        raise InputError(f"--up {up.round(3).tolist()}: {angle:.0f}° from the wall's normal "
                         f"(need ≥ {s.min_up_angle_deg:.0f}°; up runs along a wall, not into "
                         "it)")
    z = up - (up @ normal) * normal
    return z / np.linalg.norm(z)


def support_frame(points: np.ndarray, up: np.ndarray | None = None,
                  s: WallSettings = WallSettings(), name: str = "points") -> WallFrame:
    """The support frame of a camera-frame cloud ``(N, 3)`` (metres; non-finite rows
    dropped); ``up`` in the camera frame, or ``None`` for a level camera.
    :class:`InputError` naming ``name`` when there is no wall plane, nothing stands off it,
    or ``up`` runs into the wall."""
    a = np.asarray(points, float)
    a = a[np.isfinite(a).all(axis=1)]
    if len(a) < s.min_structure_points:
        raise InputError(f"{name}: {len(a)} finite points, need at least {s.min_structure_points}")
    rng_m = float(np.median(np.linalg.norm(a, axis=1)))
    if rng_m > MM_MEDIAN_RANGE_M:
        raise InputError(f"{name}: median range {rng_m:.3g} m from the camera — a cloud in "
                         "millimetres? clouds must be in metres (pass --units mm to convert)")
    a = np.asarray(o3d.geometry.PointCloud(o3d.utility.Vector3dVector(a[np.lexsort(a.T[::-1])]))
                   .voxel_down_sample(s.voxel_m).points)
    n, d, wall = _plane(a, s)
    if wall.mean() < s.min_wall_share:
        raise InputError(f"{name}: no wall plane (the largest plane holds "
                         f"{100 * wall.mean():.0f} % "
                         f"of the points, need ≥ {100 * s.min_wall_share:.0f} %) — is the wall "
                         "behind the hook in view?")
    z = _up_in_wall(n, up, s)
    rot = np.stack([n, np.cross(z, n), z])  # rows: the support axes in the camera frame
    height = a @ n + d  # signed distance in front of the wall
    s = _for_noise(s, wall_noise(height))
    off = a[(height > s.off_wall_m) & (height < s.max_reach_m)]
    structure = _structure(off, off @ n + d, s)
    if structure is None:
        raise InputError(f"{name}: no structure stands off the wall plane (no cluster of ≥ "
                         f"{s.min_structure_points} points reaching within "
                         f"{100 * s.touch_m:.1f} cm of it) — is the hook in view?")
    foot = _footprint(structure @ rot.T, -d, s)
    origin = rot.T @ np.array([-d, *_mount(foot, s)])  # on the plane
    t = np.eye(4)
    t[:3, :3] = rot
    t[:3, 3] = -rot @ origin
    seen = below_seen((a @ rot.T)[np.abs(height) <= s.off_wall_m, 1:], foot, s)
    warnings = ()
    if seen < s.min_below_seen:
        warnings = (f"{name}: the wall below the hook's foot is hidden from this camera "
                    f"({100 * seen:.0f} % of the band {100 * s.below_gap_m:.1f}–"
                    f"{100 * (s.below_gap_m + s.below_band_m):.1f} cm under it seen, need ≥ "
                    f"{100 * s.min_below_seen:.0f} %): the foot's lower edge, and so the "
                    "frame's height, may be a centimetre or more off — view the hook from "
                    "lower down, or pass --frame with a known pose",)
    return WallFrame(t, structure @ rot.T + t[:3, 3], int(wall.sum()), len(a), seen, warnings)


def wall_noise(height: np.ndarray) -> float:
    """The depth noise across the wall (σ, m), from the points behind the fitted plane:
    nothing stands behind a wall, so they are the noise's near half alone (a half-normal's
    median is 0.6745 σ); the structure in front does not bias it."""
    behind = -height[(height < 0) & (height > -0.05)]
    return float(np.median(behind) / 0.6745) if len(behind) >= 50 else 0.0


def _for_noise(s: WallSettings, sigma: float) -> WallSettings:
    """``s`` with the wall's band widened to ``noise_k`` σ where that exceeds ``off_wall_m``
    (a noisy wall's far points would stand off it as a sheet and pass for the hook), the
    touch and footprint bands moved out with it."""
    grow = max(0.0, s.noise_k * sigma - s.off_wall_m)
    if grow == 0.0:
        return s
    return replace(s, off_wall_m=s.off_wall_m + grow, touch_m=s.touch_m + grow,
                   footprint_m=s.footprint_m + grow)


def _footprint(local: np.ndarray, wall_x: float, s: WallSettings) -> np.ndarray:
    """``[[y_lo, z_lo], [y_hi, z_hi]]``: the box (1–99 % quantiles) of the footprint, the
    points of the structure ``local`` (support axes; the wall plane at x = ``wall_x``)
    within ``footprint_m`` of the wall."""
    return np.quantile(local[local[:, 0] - wall_x <= s.footprint_m, 1:], [0.01, 0.99], axis=0)


def _mount(foot: np.ndarray, s: WallSettings) -> np.ndarray:
    """(y, z) of the mount from the footprint's box: across, its centre; up,
    ``mount_above_m`` over its lower edge, or its centre when it is lower than twice that."""
    (y_lo, z_lo), (y_hi, z_hi) = foot
    return np.array([(y_lo + y_hi) / 2, min(z_lo + s.mount_above_m, (z_lo + z_hi) / 2)])


def below_seen(wall_yz: np.ndarray, foot: np.ndarray, s: WallSettings) -> float:
    """Share of the ``below_cell_m`` cells of the band under the footprint (``foot``, as
    :func:`_footprint` gives it; the band ``below_gap_m`` under its lower edge,
    ``below_band_m`` tall, across its width) that hold at least one of the wall's points
    ``wall_yz (M, 2)`` (support axes y, z)."""
    (y_lo, z_lo), (y_hi, _) = foot
    cell = s.below_cell_m
    lo = np.array([y_lo, z_lo - s.below_gap_m - s.below_band_m])
    shape = np.maximum(1, np.round([(y_hi - y_lo) / cell, s.below_band_m / cell]).astype(int))
    idx = np.floor((wall_yz - lo) / cell).astype(int)
    inside = (idx >= 0).all(1) & (idx < shape).all(1)
    return len(np.unique(idx[inside], axis=0)) / int(np.prod(shape))


def _structure(off: np.ndarray, height: np.ndarray, s: WallSettings) -> np.ndarray | None:
    """The structure in ``off``: the largest DBSCAN cluster that reaches the wall, with every
    other cluster of at least ``min_part_points`` within ``reach_m`` of it (an arm in front
    of its plate cuts the plate's view in pieces; an arm seen end-on shows its tip alone, its
    sides lost at grazing angles); ``None`` when no cluster reaches the wall."""
    if len(off) < s.min_structure_points:
        return None
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(off))
    labels = np.asarray(pcd.cluster_dbscan(s.cluster_eps_m, s.cluster_min_points))
    touching = [c for c in np.unique(labels[labels >= 0]) if height[labels == c].min() <= s.touch_m]
    if not touching:
        return None
    sizes = {c: int((labels == c).sum()) for c in touching}
    main = max(touching, key=lambda c: (sizes[c], -c))
    if sizes[main] < s.min_structure_points:
        return None
    tree = cKDTree(off[labels == main])
    keep = [c for c in np.unique(labels[labels >= 0])
            if c == main or ((labels == c).sum() >= s.min_part_points
                             and tree.query(off[labels == c])[0].min() <= s.reach_m)]
    return off[np.isin(labels, keep)]
