"""Arms of a supporting item from its mesh alone: the mesh-only counterpart of the strokes
``mesh_gen`` draws (:mod:`skt_lib.geometry.supports`), so that an imported hook gets a hang
region and a difficulty level by the same rules as a generated one.

The mesh (support frame, docs/design.md §3) is filled on a voxel grid (ray-parity occupancy); each
filled voxel's distance to the nearest empty one approximates the local section radius. An
*arm* is a shortest path through the filled voxels from the wall plate (x ≤
:data:`PLATE_THICKNESS_M`) to a tip, each step weighted by the inverse square of that
radius, so the path keeps to the middle of the tube: the first tip is the voxel farthest
from the wall along the shape; every further tip is the farthest voxel at least
:data:`BRANCH_MIN_M` (along the shape) from every arm found so far and in the hang region
(x ≥ ``HANG_MIN_X_M``). Where an arm runs along another arm's path (a rack's bar) the
shared part is cut off: the arm starts where it leaves the others.

Where it differs from the strokes of a generated item (documented in docs/cli.md):
the centreline is smoothed voxel centres (about a quarter of the voxel pitch off a true
tube axis), a square section counts as round with its inscribed radius, and a knob or any
other bulge is a stretch of larger radius (see :func:`mesh_difficulty`), not a sphere.
"""

from dataclasses import dataclass

import numpy as np
import open3d as o3d
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from skt_lib.config.mesh_gen import MeshGenParams
from skt_lib.errors import GenerationFailed, MeshError
from skt_lib.geometry.convex import Mesh
from skt_lib.geometry.supports import (
    HANG_MIN_X_M,
    PLATE_THICKNESS_M,
    Difficulty,
    Stroke,
    SupportShape,
    measure_difficulty,
)

#: Voxel edge (m) of the grid the mesh is filled on.
PITCH_M = 0.001
#: A further arm's tip lies at least this far, along the shape, from the arms found before.
BRANCH_MIN_M = 0.02
#: At most this many arms are returned (the rest are small side branches).
MAX_ARMS = 6
#: The centred polyline is simplified (Ramer–Douglas–Peucker) to within this distance:
#: voxel steps are not turns.
SIMPLIFY_M = 0.0001
#: Where an arm branches off (:func:`_past_junctions`): solid in a ball of this many section
#: radii over this many times the arm's median.
JUNCTION_BALL, JUNCTION_RATIO = 2.0, 1.3
#: A stretch of an arm is a bulge (knob) where its radius exceeds the arm's by this.
BULGE_M = 0.0015


@dataclass(frozen=True)
class Arm:
    points: np.ndarray  # (M, 3) centreline (simplified), from where it leaves the rest to its tip
    radius: float  # the arm's section radius (median over the arm)
    dense: np.ndarray  # (K, 3) the centreline before simplification, about a voxel apart
    dense_radii: np.ndarray  # (K,) section radius at each of ``dense``


def _occupancy(mesh: Mesh, pitch: float) -> tuple[np.ndarray, np.ndarray]:
    """Filled voxels of ``mesh``: (boolean grid with one empty voxel of margin, grid origin)."""
    lo = mesh.vertices.min(axis=0) - 1.5 * pitch
    shape = np.ceil((mesh.vertices.max(axis=0) + 1.5 * pitch - lo) / pitch).astype(int)
    if np.prod(shape) > 40_000_000:
        raise MeshError(f"mesh spans {shape * pitch} m: too large for a supporting item")
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(mesh.vertices.astype(np.float32)),
                        o3d.core.Tensor(mesh.faces.astype(np.uint32)))
    idx = np.stack(np.meshgrid(*[np.arange(n) for n in shape], indexing="ij"), -1).reshape(-1, 3)
    centres = (lo + (idx + 0.5) * pitch).astype(np.float32)
    occ = scene.compute_occupancy(o3d.core.Tensor(centres), nsamples=3).numpy() > 0.5
    return occ.reshape(shape), lo


def _graph(occ: np.ndarray, radius: np.ndarray, pitch: float):
    """Sparse 26-neighbour graph of the filled voxels; (weighted, unweighted) edge lengths."""
    flat = -np.ones(occ.shape, dtype=np.int64)
    cells = np.argwhere(occ)
    flat[tuple(cells.T)] = np.arange(len(cells))
    rows, cols, lengths = [], [], []
    offsets = [o for o in np.ndindex(3, 3, 3) if o != (1, 1, 1)]
    for off in offsets:
        d = np.asarray(off) - 1
        nb = cells + d
        ok = np.all((nb >= 0) & (nb < occ.shape), axis=1)
        j = np.full(len(cells), -1)
        j[ok] = flat[tuple(nb[ok].T)]
        keep = j >= 0
        rows.append(np.flatnonzero(keep))
        cols.append(j[keep])
        lengths.append(np.full(keep.sum(), pitch * np.linalg.norm(d)))
    r, c, ln = np.concatenate(rows), np.concatenate(cols), np.concatenate(lengths)
    rad = radius[tuple(cells.T)]
    w = ln / np.square(0.5 * (rad[r] + rad[c]))
    n = len(cells)
    return cells, coo_matrix((w, (r, c)), (n, n)).tocsr(), coo_matrix((ln, (r, c)), (n, n)).tocsr()


def _centre(points: np.ndarray, solid: cKDTree, radius: float, rounds: int = 4) -> np.ndarray:
    """Voxel-path points moved onto the tube's axis: each to the centroid of the filled
    voxels within ``radius`` of it, ``rounds`` times (a mean shift; on a tube the centroid
    of a ball's solid part lies nearer the axis than the ball's centre)."""
    pts = points.copy()
    for _ in range(rounds):
        near = solid.query_ball_point(pts, max(radius, 2 * PITCH_M))
        pts = np.stack([solid.data[i].mean(axis=0) if i else p for i, p in zip(near, pts)])
    return pts


def _even(points: np.ndarray, radii: np.ndarray, step: float = 0.001, sigma: float = 0.002
          ) -> tuple[np.ndarray, np.ndarray]:
    """The polyline resampled every ``step`` of arc length, smoothed by a Gaussian of
    ``sigma`` (arc length) — the voxel staircase out, bends of a few mm radius kept — with
    its radii carried over; the ends stay where they are."""
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    if s[-1] < 2 * step:
        return points, radii
    u = np.linspace(0.0, s[-1], int(np.ceil(s[-1] / step)) + 1)
    w = np.exp(-0.5 * ((u[:, None] - s[None]) / sigma) ** 2)
    w /= w.sum(axis=1, keepdims=True)
    out = w @ points
    out[0], out[-1] = points[0], points[-1]
    return out, np.interp(u, s, radii)


def _past_junctions(points: np.ndarray, solid: cKDTree, radius: float) -> int:
    """Index where the arm proper starts: past the last point of its first half where the
    solid within ``JUNCTION_BALL`` section radii holds over ``JUNCTION_RATIO`` times the
    arm's median (the wall plate, a rack's bar: anything the arm branches from), and in
    front of the plate."""
    counts = np.array([len(i) for i in solid.query_ball_point(points, JUNCTION_BALL * radius)])
    s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(points, axis=0), axis=1))])
    thick = np.flatnonzero((counts > JUNCTION_RATIO * np.median(counts)) & (s <= 0.5 * s[-1]))
    start = int(thick.max()) + 1 if len(thick) else 0
    front = np.flatnonzero(points[:, 0] >= PLATE_THICKNESS_M)
    start = max(start, int(front.min()) if len(front) else 0)
    return min(start, len(points) - 2)


def _simplify(points: np.ndarray, tol: float) -> np.ndarray:
    """Indices of ``points`` kept by Ramer–Douglas–Peucker with tolerance ``tol`` (m)."""
    keep = np.zeros(len(points), bool)
    keep[[0, -1]] = True
    stack = [(0, len(points) - 1)]
    while stack:
        a, b = stack.pop()
        if b - a < 2:
            continue
        ab = points[b] - points[a]
        rel = points[a + 1:b] - points[a]
        ln = np.linalg.norm(ab)
        d = (np.linalg.norm(np.cross(rel, ab), axis=1) / ln if ln > 0
             else np.linalg.norm(rel, axis=1))
        k = int(np.argmax(d))
        if d[k] > tol:
            keep[a + 1 + k] = True
            stack += [(a, a + 1 + k), (a + 1 + k, b)]
    return np.flatnonzero(keep)


def find_arms(mesh: Mesh, pitch: float = PITCH_M) -> list[Arm]:
    """Every arm of ``mesh`` (support frame), longest first (module docstring)."""
    occ, lo = _occupancy(mesh, pitch)
    radius = ndimage.distance_transform_edt(occ) * pitch
    cells, weighted, plain = _graph(occ, radius, pitch)
    xyz = lo + (cells + 0.5) * pitch
    wall = np.flatnonzero(xyz[:, 0] <= PLATE_THICKNESS_M)
    if not len(wall):
        raise MeshError("no part of the mesh touches the wall plate (x ≤ 1 cm): not mounted")
    along = dijkstra(plain, indices=wall, min_only=True)
    _, pred, _ = dijkstra(weighted, indices=wall, min_only=True, return_predecessors=True)
    reach = np.where(np.isfinite(along), along, -1.0)
    solid = cKDTree(xyz)
    paths: list[np.ndarray] = []
    taken = np.full(len(cells), np.inf)
    while len(paths) < MAX_ARMS:
        cand = np.flatnonzero((taken >= BRANCH_MIN_M) & (xyz[:, 0] >= HANG_MIN_X_M) & (reach > 0))
        if not len(cand):
            break
        tip = cand[np.argmax(reach[cand] if not paths else taken[cand])]
        path = [tip]
        while pred[path[-1]] >= 0:
            path.append(pred[path[-1]])
        paths.append(np.asarray(path[::-1]))
        taken = np.minimum(taken, dijkstra(plain, indices=paths[-1], min_only=True))
    if not paths:
        raise MeshError("no arm reaches the hang region (x ≥ 2.5 cm from the wall)")
    arms = []
    for k, path in enumerate(paths):
        rad = radius[tuple(cells[path].T)]
        body = float(np.median(rad))
        others = [paths[j] for j in range(len(paths)) if j != k]
        if others:  # cut where this arm last runs along another (within a section radius)
            d, _ = cKDTree(xyz[np.concatenate(others)]).query(xyz[path])
            shared = np.flatnonzero(d <= body)
            if len(shared) and shared.max() + 2 < len(path):
                path, rad = path[shared.max() + 1:], rad[shared.max() + 1:]
        # the path ends on the tip's surface: cut the end cap back to the last medial voxel
        medial = np.flatnonzero(rad >= 0.75 * body)
        end = int(medial.max()) + 1 if len(medial) else len(path)
        pts, rad = _even(_centre(xyz[path[:end]], solid, body), rad[:end])
        start = _past_junctions(pts, solid, body)
        pts, rad = pts[start:], rad[start:]
        arms.append(Arm(pts[_simplify(pts, SIMPLIFY_M)], float(np.median(rad)), pts, rad))
    return arms


def hang_candidates(mesh: Mesh, p: MeshGenParams, arm_index: int | None = None
                    ) -> tuple[list[tuple[Difficulty, Arm]], list[Arm]]:
    """The arms of ``mesh`` an object may hang on, each with its difficulty by
    :func:`measure_difficulty`, in the order to try them; and every arm.

    ``arm_index`` given: ``arms[arm_index]`` alone. Otherwise every arm that has a hang
    region, the arm whose hang point is lowest (to the nearest 5 mm) first, then the one
    nearest the mount point sideways (a fork's prongs, a rack's pegs: the caller tries them
    in turn). The other arms stand for the other strokes (clearance above the arm);
    stretches of an arm beyond its hang point whose radius exceeds the arm's by
    :data:`BULGE_M` count as knobs (blocking height)."""
    arms = find_arms(mesh)
    measured = []
    for arm in arms:
        shape = SupportShape("user", tuple(Stroke(a.points, a.radius, False) for a in
                                           [arm, *[o for o in arms if o is not arm]]))
        try:
            measured.append((arm, shape, measure_difficulty(shape, p)))
        except GenerationFailed as err:  # this arm cannot hang (no hang region, slides off)
            measured.append((arm, shape, err))
    if arm_index is not None:
        if not 0 <= arm_index < len(arms):
            raise MeshError(f"arm {arm_index}: the mesh has {len(arms)} arm(s)")
        chosen = [measured[arm_index]]
    else:
        chosen = sorted((m for m in measured if isinstance(m[2], Difficulty)),
                        key=lambda m: (round(m[2].hang_point[2] / 0.005),
                                       abs(m[2].hang_point[1])))
    if not chosen or not isinstance(chosen[0][2], Difficulty):
        reasons = "; ".join(str(m[2]) for m in measured if not isinstance(m[2], Difficulty))
        raise MeshError(f"no arm to hang on: {reasons}")
    return [(_with_knobs(arm, shape, diff, p), arm) for arm, shape, diff in chosen], arms


def _with_knobs(arm: Arm, shape: SupportShape, diff: Difficulty, p: MeshGenParams
                ) -> Difficulty:
    c = np.asarray(diff.hang_point)
    i = int(np.argmin(np.linalg.norm(arm.dense - c, axis=1)))
    bulges = tuple((tuple(q), float(r)) for q, r in zip(arm.dense[i + 1:], arm.dense_radii[i + 1:])
                   if r > arm.radius + BULGE_M)
    return measure_difficulty(SupportShape("user", shape.strokes, bulges), p) if bulges else diff


def mesh_difficulty(mesh: Mesh, p: MeshGenParams, arm_index: int | None = None
                    ) -> tuple[Difficulty, Arm, list[Arm]]:
    """(difficulty, the first arm to hang on, every arm) of ``mesh``: the first of
    :func:`hang_candidates`."""
    candidates, arms = hang_candidates(mesh, p, arm_index)
    diff, arm = candidates[0]
    return diff, arm, arms
