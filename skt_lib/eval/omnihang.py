"""OmniHang-style baseline: RRT-Connect to a privileged hanging pose under partial observability.

The paper's OmniHang baseline is given the ground-truth hanging pose of the object and plans
the approach with OMPL RRT-Connect, checking collisions against the *partial* point cloud the
method observes. This module reproduces that, adapted to the SKT interface (``T`` keypoint
positions in the support frame, ξ_0 = release at the hang first, ξ_{T-1} = start last):

- **Search space.** Keypoint *positions* in R^3 (``RealVectorStateSpace(3)``), bounded by the
  cloud's bounding box ∪ start ∪ goal grown by :data:`BOUNDS_MARGIN_M`, clipped to the free
  side of the wall (x ≥ 0). At every state the object keeps its hanging orientation
  (``hang[:3, :3]``). Execution uses the SKT frames instead
  (:func:`skt_lib.geometry.skt.executed_path`: x follows the motion), which differ from
  the planned orientation where the path turns; the last ``lead_in_m`` is a straight line along
  the hanging frame's x axis, whose rule frame anchors the SKT frames, so the object comes to
  its hanging orientation: the end of the path agrees with execution.
- **Collision check.** :class:`CloudClearance`: the least distance from the object's surface
  samples (placed at the keypoint pose) to the observed cloud points (a k-d tree) and to the
  wall plane x = 0; a state is valid when that distance is at least ``clearance_m``.
  *Deviation*: OmniHang learns a collision estimator. A learned estimator would need its own
  training data and stage; the distance check against the observed points keeps the condition
  that matters for the comparison — the planner only knows what the partial cloud shows — and
  is exact wherever the cloud sees the support. Parts of the support the cameras miss are
  free space to this planner, as they are to the original.
- **Goal.** The object at the true hanging pose always touches the support, so it is never
  clear of the cloud there. The release point is the hanging keypoint lifted in steps of
  ``lift_step_m`` (at most ``max_lift_m``) until the object there, and along the straight
  lead-in to it, is clear: released there it drops into the hang. RRT-Connect plans from the
  start (``hang + start_offset_m``, the centre of ``rrt_skts``' start region) to the lead-in
  point ``release − lead_in_m · x_hang``; the lead-in is appended afterwards.
- **Post-processing.** Seeded random shortcutting (a :class:`numpy.random.Generator` from
  ``seed``, a fixed number of attempts, each checked densely) of the RRT part — *not* OMPL's
  time-limited simplifiers, whose output depends on machine speed — then arc-length
  resampling to ``T`` waypoints (:func:`skt_lib.geometry.skt.resample`), reversed to
  ξ_0-first order.
- **Determinism.** RRT-Connect's samples come from OMPL's process-global seed generator,
  which is re-seeded from ``seed`` right before the planner is built (OMPL logs an error that
  re-seeding after the first RNG "will not lead to deterministic sampling"; it does re-seed
  the generator, so every RNG made afterwards is seeded from ``seed``; the message is
  silenced). RRT-Connect stops at the first connection or when it has spent ``max_checks``
  collision checks — a budget counted, not timed, so whether a plan is solved does not depend
  on the machine's speed either. Not thread-safe: plan in processes, not threads, when
  planning in parallel.
- **Failure.** When the start or goal cannot be made valid or no path is found within
  ``max_checks`` collision checks, the plan is the straight line start → lead-in point →
  release, resampled to ``T``, with ``solved=False``: a best-effort path that the trial then judges.

Guarantee of a solved plan: the polyline the planner certified (RRT path after shortcutting,
plus the lead-in) is clear by ``clearance_m`` at every check point ``check_step_m`` apart.
The output's waypoints are points of that polyline, and the chords between them leave it by
at most half the waypoint spacing, so every pose of a dense re-interpolation of the output at
the hanging orientation is clear by at least
``clearance_m − (spacing + check_step_m) / 2``; :attr:`OmniHangPlan.clearance_m` reports
the measured value.
"""

import contextlib
import logging
import time
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from skt_lib.geometry.skt import arc_length, resample

log = logging.getLogger(__name__)

BOUNDS_MARGIN_M = 0.08  # same margin as rrt_skts' planning bounds
MIN_CLOUD_POINTS = 10
Bounds = tuple[np.ndarray, np.ndarray]


@dataclass(frozen=True)
class OmniHangSettings:
    start_offset_m: tuple[float, float, float] = (0.12, 0.0, 0.05)
    """Start keypoint relative to the hanging keypoint (support frame): in front and above,
    the centre of ``rrt_skts``' start region."""
    clearance_m: float = 0.003
    """Least distance from any object sample to any cloud point (and to the wall) for a
    state to be valid."""
    lead_in_m: float = 0.01
    """Length of the final straight stretch along the hanging frame's x axis."""
    max_lift_m: float = 0.02
    """Largest lift of the release point above the hanging keypoint."""
    lift_step_m: float = 0.002
    """Lift increment while searching for a clear release point."""
    range_m: float = 0.01
    """RRT-Connect's longest edge."""
    check_step_m: float = 0.002
    """Motion-check resolution: distance between checked states along an edge."""
    max_checks: int = 20000
    """RRT-Connect's budget in collision checks (of states and along edges); only decides
    whether a plan is found, and the same on every machine (a wall-time limit would not be)."""
    shortcut_steps: int = 100
    """Random shortcut attempts (seeded, each checked densely)."""


@dataclass(frozen=True)
class OmniHangPlan:
    positions: np.ndarray
    """(T, 3) float64, metres, support frame: ξ_0 (release) first, ξ_{T-1} (start) last."""
    solved: bool
    """RRT-Connect found a path (else ``positions`` is the straight-line fallback)."""
    seconds: float
    """Planning wall time (s), shortcutting included."""
    goal: np.ndarray
    """(3,) the release point used (the hanging keypoint, lifted)."""
    n_checks: int
    """Object poses checked against the cloud (planning, lifting, shortcutting)."""
    clearance_m: float
    """Least clearance of a dense re-interpolation of ``positions`` at the hanging
    orientation (m)."""


class CloudClearance:
    """Clearance of an object, given by surface samples in its keypoint frame, to a point
    cloud and the wall plane x = 0.

    ``cloud``: (N, 3) metres, support frame. ``object_points``: (K, 3) metres, keypoint frame.
    """

    def __init__(self, cloud: np.ndarray, object_points: np.ndarray, clearance_m: float = 0.003):
        self.cloud = _check_cloud(cloud)
        self.object_points = _check_object_points(object_points)
        self.clearance_m = float(clearance_m)
        self._tree = cKDTree(self.cloud)
        self._radius = float(np.linalg.norm(self.object_points, axis=1).max())
        self.n_checks = 0
        """Poses checked so far (both methods)."""

    def _points(self, pose: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        poses = np.asarray(pose, dtype=np.float64).reshape(-1, 4, 4)
        self.n_checks += len(poses)
        pts = np.einsum("mij,kj->mki", poses[:, :3, :3], self.object_points)
        return poses, pts + poses[:, None, :3, 3]

    def clearance(self, pose: np.ndarray) -> float:
        """Least distance (m) of the object points at ``pose`` — the keypoint frame in the
        support frame, (4, 4) or (M, 4, 4) — to the cloud and to the wall (x coordinate;
        negative behind the wall)."""
        _, pts = self._points(pose)
        pts = pts.reshape(-1, 3)
        dist, _ = self._tree.query(pts, k=1)
        return min(float(pts[:, 0].min()), float(dist.min()))

    def collides(self, pose: np.ndarray) -> bool:
        """Whether any pose of ``pose`` ((4, 4) or (M, 4, 4)) is closer than ``clearance_m``
        (the same answer as ``clearance(pose) < clearance_m``, faster).

        Poses with no cloud point within the object's radius + ``clearance_m`` of the keypoint
        cannot collide with the cloud (triangle inequality) and skip the per-point query."""
        poses, pts = self._points(pose)
        if pts[..., 0].min() < self.clearance_m:
            return True
        reach = self._radius + self.clearance_m
        d0, _ = self._tree.query(poses[:, :3, 3], k=1, distance_upper_bound=reach * (1 + 1e-9))
        near = d0 <= reach
        if not near.any():
            return False
        d, _ = self._tree.query(pts[near].reshape(-1, 3), k=1,
                                distance_upper_bound=self.clearance_m)
        return bool((d < self.clearance_m).any())


def plan_omnihang(cloud: np.ndarray, hang: np.ndarray, object_points: np.ndarray, T: int,
                  settings: OmniHangSettings = OmniHangSettings(), seed: int = 0) -> OmniHangPlan:
    """Plan an SKT to the privileged hanging pose with RRT-Connect against the partial cloud.

    ``cloud``: (N ≥ 10, 3) observed points, metres, support frame. ``hang``: (4, 4) keypoint
    frame at the hang in the support frame (rigid). ``object_points``: (K ≥ 1, 3) object
    surface samples in the keypoint frame. ``T``: number of waypoints (≥ 2). Never raises for
    an unsolvable scene (see the module docstring); raises ``ValueError`` for bad input."""
    hang = _check_hang(hang)
    if int(T) != T or T < 2:
        raise ValueError(f"T: need an integer of at least 2 waypoints, got {T}")
    if int(seed) != seed or seed < 0:
        raise ValueError(f"seed: need a non-negative integer, got {seed}")
    checker = CloudClearance(cloud, object_points, settings.clearance_m)
    t0 = time.perf_counter()
    rot = hang[:3, :3]
    x_hang = rot[:, 0]
    start = hang[:3, 3] + np.asarray(settings.start_offset_m, dtype=np.float64)
    release = _release_point(checker, hang, settings)
    solved = release is not None and not checker.collides(_poses(rot, start[None]))
    release = hang[:3, 3].copy() if release is None else release
    lead = release - settings.lead_in_m * x_hang
    path = None
    if solved:
        bounds = _bounds(checker.cloud, start, np.stack([lead, release]))
        path = _rrt_connect(checker, rot, start, lead, bounds, settings, seed)
    solved = path is not None
    if solved:
        path = _shortcut(checker, rot, path, settings, np.random.default_rng(seed))
    else:
        log.info("OmniHang: no path (start/goal invalid or RRT-Connect out of checks)")
        path = np.stack([start, lead])
    positions = resample(np.vstack([path, release]), int(T))[::-1].copy()
    seconds = time.perf_counter() - t0
    n_checks = checker.n_checks
    clear = checker.clearance(_poses(rot, _densify(positions, settings.check_step_m)))
    return OmniHangPlan(positions=positions, solved=solved,
                        seconds=seconds, goal=release, n_checks=n_checks, clearance_m=clear)


# -- input checks ---------------------------------------------------------------------------

def _check_cloud(cloud: np.ndarray) -> np.ndarray:
    cloud = np.asarray(cloud, dtype=np.float64)
    if cloud.ndim != 2 or cloud.shape[1] != 3 or len(cloud) < MIN_CLOUD_POINTS:
        raise ValueError(f"cloud: expected (N>={MIN_CLOUD_POINTS}, 3), got {cloud.shape}")
    if not np.isfinite(cloud).all():
        raise ValueError("cloud: contains non-finite values")
    return cloud


def _check_object_points(points: np.ndarray) -> np.ndarray:
    points = np.asarray(points, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3 or len(points) == 0:
        raise ValueError(f"object_points: expected (K>=1, 3), got {points.shape}")
    if not np.isfinite(points).all():
        raise ValueError("object_points: contains non-finite values")
    return points


def _check_hang(hang: np.ndarray) -> np.ndarray:
    hang = np.asarray(hang, dtype=np.float64)
    if hang.shape != (4, 4) or not np.isfinite(hang).all():
        raise ValueError(f"hang: expected a finite (4, 4) transform, got shape {hang.shape}")
    rot = hang[:3, :3]
    if (not np.allclose(rot.T @ rot, np.eye(3), atol=1e-6) or np.linalg.det(rot) < 0
            or not np.allclose(hang[3], [0, 0, 0, 1])):
        raise ValueError("hang: not a rigid transform (rotation not orthonormal, det != 1, or "
                         "last row != [0, 0, 0, 1])")
    return hang


# -- geometry helpers -----------------------------------------------------------------------

def _poses(rot: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """Keypoint poses (M, 4, 4) with rotation ``rot`` at ``positions (M, 3)``."""
    out = np.tile(np.eye(4), (len(positions), 1, 1))
    out[:, :3, :3] = rot
    out[:, :3, 3] = positions
    return out


def _densify(path: np.ndarray, step: float) -> np.ndarray:
    """Points along the polyline ``path (N, 3)`` at most ``step`` apart, vertices included."""
    out = [path[:1]]
    for a, b in zip(path[:-1], path[1:]):
        n = max(1, int(np.ceil(np.linalg.norm(b - a) / step)))
        u = np.arange(1, n + 1)[:, None] / n
        out.append((1 - u) * a + u * b)
    return np.vstack(out)


def _segment_clear(checker: CloudClearance, rot: np.ndarray, a: np.ndarray, b: np.ndarray,
                   step: float) -> bool:
    return not checker.collides(_poses(rot, _densify(np.stack([a, b]), step)))


def _release_point(checker: CloudClearance, hang: np.ndarray,
                   s: OmniHangSettings) -> np.ndarray | None:
    """The hanging keypoint lifted by the least multiple of ``lift_step_m`` (≤ ``max_lift_m``)
    at which the object and its straight lead-in are clear; ``None`` if there is none."""
    rot, x_hang = hang[:3, :3], hang[:3, 0]
    n_steps = int(np.floor(s.max_lift_m / s.lift_step_m + 1e-9))
    for i in range(n_steps + 1):
        release = hang[:3, 3] + np.array([0.0, 0.0, i * s.lift_step_m])
        if _segment_clear(checker, rot, release - s.lead_in_m * x_hang, release, s.check_step_m):
            return release
    return None


def _bounds(cloud: np.ndarray, start: np.ndarray, goals: np.ndarray) -> Bounds:
    """Planning bounds (low (3,), high (3,)): cloud ∪ start ∪ goals grown by
    :data:`BOUNDS_MARGIN_M`, x clipped to the free side of the wall."""
    pts = np.vstack([cloud, start, goals])
    lo, hi = pts.min(0) - BOUNDS_MARGIN_M, pts.max(0) + BOUNDS_MARGIN_M
    lo[0] = max(lo[0], 0.0)
    return lo, hi


# -- OMPL -----------------------------------------------------------------------------------

@contextlib.contextmanager
def _ompl_log_level(level: object) -> Iterator[None]:
    """Set OMPL's global log level (an ``ompl.util.LogLevel``) for the block, then restore it."""
    import ompl.util as ou

    before = ou.getLogLevel()
    ou.setLogLevel(level)
    try:
        yield
    finally:
        ou.setLogLevel(before)


def _ompl_seed(seed: int) -> int:
    """A positive 31-bit OMPL seed from a non-negative ``seed`` (OMPL ignores 0)."""
    return int(np.random.SeedSequence(int(seed)).generate_state(1)[0] % (2**31 - 1)) + 1


def _rrt_connect(checker: CloudClearance, rot: np.ndarray, start: np.ndarray, goal: np.ndarray,
                 bounds: Bounds, s: OmniHangSettings,
                 seed: int) -> np.ndarray | None:
    """RRT-Connect from ``start`` to ``goal`` (keypoint positions); the path's vertices
    (N, 3) or ``None`` when none is found within ``s.max_checks`` collision checks."""
    import ompl.base as ob
    import ompl.geometric as og
    import ompl.util as ou

    with _ompl_log_level(ou.LOG_NONE):
        ou.RNG.setSeed(_ompl_seed(seed))  # global; must precede every RNG the planner makes
    space = ob.RealVectorStateSpace(3)
    rv_bounds = ob.RealVectorBounds(3)
    for k in range(3):
        rv_bounds.setLow(k, float(bounds[0][k]))
        rv_bounds.setHigh(k, float(bounds[1][k]))
    space.setBounds(rv_bounds)
    si = ob.SpaceInformation(space)

    def is_valid(state) -> bool:
        p = np.array([state[0], state[1], state[2]])
        return not checker.collides(_poses(rot, p[None]))

    si.setStateValidityChecker(is_valid)
    si.setStateValidityCheckingResolution(s.check_step_m / space.getMaximumExtent())
    si.setup()
    a, b = space.allocState(), space.allocState()
    for k in range(3):
        a[k], b[k] = float(start[k]), float(goal[k])
    pdef = ob.ProblemDefinition(si)
    pdef.setStartAndGoalStates(a, b)
    planner = og.RRTConnect(si)
    planner.setRange(s.range_m)
    planner.setProblemDefinition(pdef)
    with _ompl_log_level(ou.LOG_WARN):
        planner.setup()
        budget = checker.n_checks + int(s.max_checks)
        status = planner.solve(ob.PlannerTerminationCondition(lambda: checker.n_checks >= budget))
    if status.getStatus() != ob.PlannerStatus.EXACT_SOLUTION:
        return None
    path = pdef.getSolutionPath()
    return np.array([[path.getState(i)[k] for k in range(3)]
                     for i in range(path.getStateCount())])


# -- post-processing ------------------------------------------------------------------------

def _point_at(path: np.ndarray, s_cum: np.ndarray, s: float) -> tuple[np.ndarray, int]:
    """The point at arc length ``s`` and the index of the segment's first vertex."""
    i = int(np.clip(np.searchsorted(s_cum, s, side="right") - 1, 0, len(path) - 2))
    seg = s_cum[i + 1] - s_cum[i]
    u = 0.0 if seg <= 0 else (s - s_cum[i]) / seg
    return (1 - u) * path[i] + u * path[i + 1], i


def _shortcut(checker: CloudClearance, rot: np.ndarray, path: np.ndarray, s: OmniHangSettings,
              rng: np.random.Generator) -> np.ndarray:
    """Random shortcutting: ``s.shortcut_steps`` attempts, each replacing the stretch between
    two random arc-length positions with a straight segment when that segment is clear.
    Endpoints are kept; consecutive duplicate vertices are removed."""
    path = _dedupe(path)
    for _ in range(s.shortcut_steps):
        if len(path) < 3:
            break
        s_cum = arc_length(path)
        s1, s2 = np.sort(rng.uniform(0.0, s_cum[-1], size=2))
        p1, i1 = _point_at(path, s_cum, s1)
        p2, i2 = _point_at(path, s_cum, s2)
        if i1 == i2:  # same segment: already straight
            continue
        if _segment_clear(checker, rot, p1, p2, s.check_step_m):
            path = _dedupe(np.vstack([path[:i1 + 1], p1, p2, path[i2 + 1:]]))
    return path


def _dedupe(path: np.ndarray, tol: float = 1e-12) -> np.ndarray:
    """``path (N, 3)`` without consecutive duplicate vertices; both endpoints are kept."""
    keep = np.concatenate([[True], np.linalg.norm(np.diff(path, axis=0), axis=1) > tol])
    keep[-1] = True
    out = path[keep]
    if len(out) >= 2 and np.linalg.norm(out[-1] - out[-2]) <= tol:
        out = np.delete(out, -2, axis=0)
    return out
