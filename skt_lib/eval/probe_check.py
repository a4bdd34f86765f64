"""``skt_flow``'s read-out ranks its samples by the training objects carried along them.

The cloud check (:mod:`skt_lib.learning.cloud_check`) carries the reference ring, the
smallest object, along a sample; after the move clear of the points
(:mod:`skt_lib.eval.clear_shift`) nearly every sample clears it, so on most supports it
cannot tell the samples apart. The objects that fail are larger: their bodies hang below
the keypoint and strike a tip or the support's arm on the way (``collided_before_hang``:
1,095 of 1,304 failed trials when every sample of the committed model ran every training
object on validation).

Here the probes are the training objects (:class:`ProbeSet`: each one's surface, evenly
sampled, in its keypoint frame). Each is carried along a sample as ``sim_eval`` executes it
(:func:`~skt_lib.geometry.skt.executed_path`, ``STEP_M``), and every probe point within
``DEPTH_M`` of an observed point counts ``(DEPTH_M − d)²``. A probe's sum ``e`` (m²) enters
a sample's score as ``log(1 + e / UNIT_M2)``, summed over the probes: an object that touches
nothing adds 0, and the logarithm weighs depth little, so the score counts the objects
that run into the seen points more than how deep any one does. The hang is included: that
is where the objects meet the hook, and a check that starts 3 cm out picks no better than
the ring. The sample with the lowest score runs; ties keep the caller's order. Only the
input cloud and the training objects are used: no mesh of the support, no test object.

Chosen on validation (40 supports × the 10 training objects; each object's pick made with
the probes of the other categories only, so that no object judges its own trial; docs/cli.md
has the runs): against the cloud check's pick of ten samples, the one-SKT row hangs 72.5 →
79.0 % with ten samples and 81.8 % with thirty (+9.2 points [+2.5, +16.5] over supports,
Very Hard 35 → 58).
"""

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial import cKDTree

from skt_lib.errors import DataError
from skt_lib.geometry.export import read_obj
from skt_lib.geometry.se3 import pose_matrix
from skt_lib.geometry.skt import executed_path
from skt_lib.io import read_table
from skt_lib.schemas import KEYPOINTS, OBJECTS

#: How near a probe point must come to an observed point to count (m).
DEPTH_M = 0.002
#: Executed-path step (m): no point within ``REACH_M`` of the keypoint moves farther per pose.
STEP_M = 0.004
REACH_M = 0.05
#: A probe's penetration sum is counted in units of this (m²) before the logarithm.
UNIT_M2 = 1e-6
#: Surface points drawn per probe object (evenly; a few fewer may come back).
N_POINTS = 600


@dataclass(frozen=True)
class ProbeSet:
    """Probe objects: ``names`` and each one's surface points ``(P, 3)`` in its keypoint
    frame (m)."""

    names: tuple[str, ...]
    points: tuple[np.ndarray, ...]

    def __post_init__(self):
        if not self.names or len(self.names) != len(self.points):
            raise ValueError(f"ProbeSet: need one point set per name, got {len(self.names)} "
                             f"names and {len(self.points)} point sets")
        for name, p in zip(self.names, self.points):
            if p.ndim != 2 or p.shape[1] != 3 or not len(p) or not np.isfinite(p).all():
                raise ValueError(f"ProbeSet: {name}: expected finite (P, 3) points, got "
                                 f"shape {p.shape}")


def probe_points(mesh, keypoint: np.ndarray, n_points: int = N_POINTS) -> np.ndarray:
    """``mesh``'s (:class:`~skt_lib.geometry.convex.Mesh`) surface, about ``n_points`` even
    samples (seeded: the same points on every run), in the frame ``keypoint (4, 4)`` (the
    keypoint frame in the object frame)."""
    import trimesh

    tm = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
    pts = np.asarray(trimesh.sample.sample_surface_even(tm, n_points, seed=0)[0], float)
    kp = np.asarray(keypoint, float).reshape(4, 4)
    return (pts - kp[:3, 3]) @ kp[:3, :3]


def load_probes(root: Path, n_points: int = N_POINTS) -> ProbeSet:
    """The training objects under the data root ``root`` (``mesh_gen``'s meshes,
    ``rotation_extraction``'s keypoints), in the objects table's order, as probes."""
    mg = Path(root) / "mesh_gen"
    objects = read_table(mg / "objects.parquet", OBJECTS)
    kps = read_table(Path(root) / "rotation_extraction" / "keypoints.parquet",
                     KEYPOINTS).set_index("object_id")
    train = objects[(objects["split"] == "train") & ~objects["is_reference"]
                    & objects["object_id"].isin(kps.index)]
    if train.empty:
        raise DataError(f"{root}: no training object with a keypoint to probe with")
    return ProbeSet(tuple(train["object_id"]), tuple(
        probe_points(read_obj(mg / o.mesh_path)[0],
                     pose_matrix(kps.loc[o.object_id, "position"], kps.loc[o.object_id, "quat"]),
                     n_points) for o in train.itertuples()))


def probe_penetrations(candidates: list[np.ndarray], cloud: np.ndarray,
                       probes: ProbeSet) -> np.ndarray:
    """``(C, O)``: per candidate SKT ``(T, 3)`` (ξ_0 first) and probe, the sum over executed
    poses and probe points of ``max(0, DEPTH_M − d)²`` (m²), ``d`` a point's distance to
    the nearest of ``cloud (N, 3)``."""
    if not len(candidates):
        raise ValueError("candidates: need at least one SKT")
    cloud = np.asarray(cloud, dtype=np.float64)
    tree, near = cKDTree(cloud), _NearCells(cloud)
    out = np.zeros((len(candidates), len(probes.names)))
    for i, c in enumerate(candidates):
        frames = executed_path(np.asarray(c, float), STEP_M, REACH_M)
        rot, pos = frames[:, :3, :3], frames[:, :3, 3]
        rows = rot.reshape(-1, 3).T  # one product for every pose: (3, 3M)
        for j, local in enumerate(probes.points):
            placed = ((local @ rows).reshape(len(local), -1, 3) + pos).reshape(-1, 3)
            placed = placed[near(placed)]  # the others lie farther than DEPTH_M from any point
            d, _ = tree.query(placed, distance_upper_bound=DEPTH_M)
            out[i, j] = np.square(np.maximum(DEPTH_M - d, 0.0)).sum()  # d = inf: no point
    return out


class _NearCells:
    """Which query points may lie within ``DEPTH_M`` of a point of ``cloud``: those in a
    cell (a cube of side ``DEPTH_M``) that is a cloud point's cell or one of its 26
    neighbours. Exact as a filter (a point within ``DEPTH_M`` of a cloud point lies at most
    one cell from it on every axis); the tree then measures the few it passes. The grid
    reaches two cells past the cloud on every side, so its border cells are never near and a
    point outside it may be clipped onto them."""

    def __init__(self, cloud: np.ndarray):
        self.lo = cloud.min(axis=0) - 2 * DEPTH_M
        cells = np.floor((cloud - self.lo) / DEPTH_M).astype(np.int64)
        self.shape = cells.max(axis=0) + 3
        grid = np.zeros(self.shape, dtype=bool)
        grid[tuple(cells.T)] = True
        near = np.zeros_like(grid)
        for dx in (-1, 0, 1):  # dilate by one cell along each axis in turn: the 27-cube
            near[max(dx, 0):self.shape[0] + min(dx, 0)] |= \
                grid[max(-dx, 0):self.shape[0] + min(-dx, 0)]
        grid, near = near, np.zeros_like(grid)
        for dy in (-1, 0, 1):
            near[:, max(dy, 0):self.shape[1] + min(dy, 0)] |= \
                grid[:, max(-dy, 0):self.shape[1] + min(-dy, 0)]
        grid, near = near, np.zeros_like(grid)
        for dz in (-1, 0, 1):
            near[:, :, max(dz, 0):self.shape[2] + min(dz, 0)] |= \
                grid[:, :, max(-dz, 0):self.shape[2] + min(-dz, 0)]
        self.grid = near

    def __call__(self, points: np.ndarray) -> np.ndarray:
        cells = np.floor((points - self.lo) / DEPTH_M).astype(np.int64)
        np.clip(cells, 0, self.shape - 1, out=cells)
        return self.grid[cells[:, 0], cells[:, 1], cells[:, 2]]


def probe_scores(penetrations: np.ndarray) -> np.ndarray:
    """Per candidate: ``Σ_probes log(1 + e / UNIT_M2)`` of :func:`probe_penetrations`."""
    return np.log1p(np.asarray(penetrations) / UNIT_M2).sum(axis=1)


def order_by_probes(candidates: list[np.ndarray], cloud: np.ndarray,
                    probes: ProbeSet) -> tuple[np.ndarray, np.ndarray]:
    """(order, scores): the candidates lowest :func:`probe_scores` first; a stable sort, so
    equal scores keep the caller's order."""
    scores = probe_scores(probe_penetrations(candidates, cloud, probes))
    return np.argsort(scores, kind="stable"), scores


def ordered(skts: list, cloud: np.ndarray, probes: ProbeSet) -> list:
    """``skts`` (:class:`~skt_lib.learning.predictor.Skt`) in :func:`order_by_probes`' order."""
    order, _ = order_by_probes([k.positions for k in skts], cloud, probes)
    return [skts[i] for i in order]
