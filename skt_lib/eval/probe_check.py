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
from functools import cached_property
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

    @cached_property
    def cells(self) -> list["_ProbeCells"]:
        """The probes' cell grids, built on first use: :data:`_GROUP` probes each."""
        n = len(self.names)
        return [_ProbeCells(self.points, range(a, min(a + _GROUP, n)))
                for a in range(0, n, _GROUP)]


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
    the nearest of ``cloud (N, 3)``.

    Measured from the probes' side: every observed point is moved into the keypoint frame of
    every executed pose of every candidate (one matrix product per :data:`CHUNK` poses), the
    probes' cell grid (:class:`_ProbeCells`) keeps the few pairs that may lie within
    ``DEPTH_M`` of some probe's points, and those are measured against each such probe's
    tree. The sums are those of placing every probe point at every pose and measuring it
    against the cloud, to the last bits of the distances (the tests check them against every
    distance), at about a sixth of the cost: one observed point per pose rather than ten
    probes' 600."""
    if not len(candidates):
        raise ValueError("candidates: need at least one SKT")
    cloud = np.asarray(cloud, dtype=np.float64)
    frames = [executed_path(np.asarray(c, float), STEP_M, REACH_M) for c in candidates]
    owner = np.repeat(np.arange(len(frames)), [len(f) for f in frames])  # pose -> candidate
    frames = np.concatenate(frames)
    rot, pos = frames[:, :3, :3], frames[:, :3, 3]
    out = np.zeros((len(candidates), len(probes.names)))
    for group in probes.cells:
        pose, point, bits = group.near(cloud, rot, pos)
        if not len(pose):
            continue
        local = np.einsum("ki,kij->kj", cloud[point] - pos[pose], rot[pose])
        for bit, j in enumerate(group.probes):
            sel = np.flatnonzero(bits & bits.dtype.type(1 << bit))
            if not len(sel):
                continue
            pairs = cKDTree(local[sel]).sparse_distance_matrix(group.trees[bit], DEPTH_M,
                                                               output_type="ndarray")
            if not len(pairs):
                continue
            # (pose, probe point) keys: each one's nearest observed point counts once
            n = len(probes.points[j])
            key = pose[sel][pairs["i"]] * n + pairs["j"]
            order = np.argsort(key, kind="stable")
            key, d = key[order], pairs["v"][order]
            first = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])
            depth = np.square(np.maximum(DEPTH_M - np.minimum.reduceat(d, first), 0.0))
            np.add.at(out[:, j], owner[key[first] // n], depth)
    return out


#: Executed poses moved into per matrix product in :meth:`_ProbeCells.near` (keeps the
#: arrays in cache: about 1.5 MB of cell coordinates per chunk of a 1,000-point cloud).
CHUNK = 64
#: Probes per cell grid: one bit each.
_GROUP = 64
#: The cell grid's side (m): half ``DEPTH_M``, so that a probe point's cells hug its ball.
CELL_M = DEPTH_M / 2
#: Cells a probe point's ball of radius ``DEPTH_M`` may reach from its own, per axis.
_REACH = int(np.ceil(DEPTH_M / CELL_M))


class _ProbeCells:
    """A cell grid (cubes of side :data:`CELL_M`) in the keypoint frame over the probes
    ``probes`` (indices into a :class:`ProbeSet`, at most :data:`_GROUP`): bit ``b`` of a
    cell is set when the cell comes within ``DEPTH_M`` of a point of the ``b``-th. Exact as a
    filter (a point within ``DEPTH_M`` of a probe point lies in such a cell), and tight: a
    probe point's cells fill about 2.6 × its ball, where the cube of 27 cells of side
    ``DEPTH_M`` around it fills 6.4 ×, and every cell passed costs a tree query. The grid
    reaches a cell past those on every side, so its border cells are empty and a point
    outside it may be clipped onto them. ``trees``: each probe's points, to measure what the
    grid passes."""

    def __init__(self, points: tuple[np.ndarray, ...], probes: range):
        self.probes = probes
        every = np.concatenate([points[j] for j in probes])
        self.lo = every.min(axis=0) - (_REACH + 1) * CELL_M
        self.shape = np.floor((every.max(axis=0) - self.lo) / CELL_M).astype(np.int64) \
            + _REACH + 2
        grid = np.zeros(self.shape, dtype=np.min_scalar_type(2 ** len(probes) - 1))
        steps = np.arange(-_REACH, _REACH + 1)
        offsets = np.stack(np.meshgrid(steps, steps, steps, indexing="ij"), -1).reshape(-1, 3)
        for bit, j in enumerate(probes):
            own = np.floor((points[j] - self.lo) / CELL_M).astype(np.int64)
            cells = own[:, None] + offsets  # (P, 7³, 3)
            low = self.lo + cells * CELL_M  # each cell's lower corner
            gap = np.maximum(np.maximum(low - points[j][:, None], 0.0),
                             points[j][:, None] - (low + CELL_M))
            # the ball reaches the cell; the slack keeps cells a rounding away
            hit = cells[np.square(gap).sum(-1) < (DEPTH_M + 1e-9) ** 2]
            grid[tuple(hit.T)] |= grid.dtype.type(1 << bit)
        self.flat = grid.ravel()
        self.trees = [cKDTree(points[j]) for j in probes]

    def near(self, cloud: np.ndarray, rot: np.ndarray,
             pos: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(pose, point, bits): every pair of an executed pose (``rot (K, 3, 3)``, ``pos (K,
        3)``) and a point of ``cloud (N, 3)`` that, in that pose's keypoint frame, falls in
        a cell with bits set, and those bits."""
        s, n = self.shape, len(cloud)
        poses, points, bits = [], [], []
        for a in range(0, len(rot), CHUNK):
            r, p = rot[a:a + CHUNK] / CELL_M, pos[a:a + CHUNK]
            # cell coordinates axis by axis, (3, k, N): ((x − t) R − lo) / CELL_M
            u = (r.transpose(2, 0, 1).reshape(-1, 3) @ cloud.T).reshape(3, len(r), n)
            u -= (np.einsum("ki,kij->jk", p, r) + (self.lo / CELL_M)[:, None])[:, :, None]
            cells = np.floor(u, out=u).astype(np.int64)
            for axis in range(3):
                np.clip(cells[axis], 0, s[axis] - 1, out=cells[axis])
            b = self.flat[(cells[0] * s[1] + cells[1]) * s[2] + cells[2]]
            k, i = np.nonzero(b)
            poses.append(k + a)
            points.append(i)
            bits.append(b[k, i])
        return np.concatenate(poses), np.concatenate(points), np.concatenate(bits)


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
