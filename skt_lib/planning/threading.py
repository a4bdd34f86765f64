"""Threading planner: SKTs that are collision-free *as executed*.

An SKT is executed with its rotation-minimizing frames (:func:`skt_lib.geometry.skt.skt_frames`:
x = direction of motion, the roll carried along the path from the hanging orientation), so the
object's orientation is tied to the way it moves — it is threaded along the path like a ring
along a wire, over an upturned tip and down along it as well as straight in. This planner
searches keypoint positions only, with every pose checked at exactly the frame execution will
give it:

- a tree grows backward from the hang ξ_0 with edges of ``step_m``; the first ``lead_in_m``
  is a straight line along the arrival direction — the hanging keypoint's x axis or, where
  that is blocked (an upright in front of the hang), the nearest clear direction turned from
  it — whose rule frame anchors the SKT frames: the hanging orientation the object ends at;
- each node carries the frame its parent's is transported to along the edge (the minimal
  rotation between consecutive motion directions), so frames are defined while the tree
  grows, for any direction of motion — vertical included (no pitch limit); an edge may turn
  the motion by at most ``max_turn_deg`` from the next edge;
- the release ξ_0 is the hanging keypoint, or where the probe does not fit there (a ring
  tilted along an angled peg meets the wall plate at the hang), a point at most
  ``max_release_offset_m`` (≤ 4 mm) from it, lifted above it and/or moved back along the
  arrival (the object drops or slides the rest of the way in); nothing is set back in front
  of the hang beyond that, so every SKT this planner returns ends at the hang;
- every pose is checked with the *probe*: the reference object (and, when asked, every
  training object) at its own keypoint frame, against the support and the wall. The frame at
  a waypoint depends on the motion arriving at it, so adding a child re-checks its parent's
  edge with the orientation that child gives it;
- samples are drawn in the start region (``goal_bias``), near the support's surface
  (``surface_bias``, from the caller's ``sample_near``: points offset from the mesh along its
  normals, so the tree follows hooks and tips of any shape, imported meshes included), near
  the hanging arm's threading route (``route_bias``, from the caller's ``sample_route``:
  :mod:`skt_lib.planning.route`), or uniformly in the bounds; a ``plane_bias`` share of them,
  of every kind but the route's, is moved onto the
  *threading plane* (:func:`threading_plane`: the vertical plane through the hang that holds
  the arrival direction), where a ring goes over a tip and down it without turning sideways.
  A path that leaves that plane to pass a tip beside it turns the object about the vertical
  and, through the transported frames, rolls it: its start orientation ends up far from the
  hanging one (up to 180°), which the arm cannot follow and a learned template cannot average;
- when a node reaches the start region, the path is joined straight to the canonical
  start (when given: the region's centre) from the first of its vertices where that stretch
  keeps the turn limit and is clear, so SKTs of one support start at one point and differ only where the support makes
  them; then it is shortcut (random, seeded; a shortcut rolls the frames of everything
  before it, so every segment whose frames change is re-checked), resampled to the evaluated
  ``T`` waypoints, and checked once more as executed at that resolution; a path that fails
  there is dropped and a fresh tree grows (the same budget). What passes is what
  ``sim_eval`` executes;
- :func:`plan_threading_many` reads many SKTs out of **one** tree (every SKT of a support
  ends at the same hang, and the threading from it is the costly part): each SKT takes a
  leaf of its own and its own start, and is joined, shortcut and checked as above.

Deterministic: the caller's generator drives every sample; the budget is counted in checks.
"""

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from skt_lib.errors import ItemFailure
from skt_lib.geometry.se3 import skt_rotation
from skt_lib.geometry.skt import cross3, executed_path, minimal_rotation, resample, skt_frames


#: Release offsets tried first: lifts above the hang in steps of this (m); then the rest of
#: a grid of :data:`RELEASE_STEP_M` (lift and back along the arrival).
LIFT_STEP_M = 0.002
RELEASE_STEP_M = 0.001
#: A tree that has added fewer than STUCK_NODES nodes after STUCK_CHECKS checks is stuck at
#: its release: the next release candidate is tried.
STUCK_CHECKS, STUCK_NODES = 1500, 3


class ThreadingFailed(ItemFailure):
    reason = "no_path"


@dataclass(frozen=True)
class ThreadSettings:
    step_m: float  # tree edge length
    max_turn_deg: float  # largest change of motion direction between consecutive edges
    lead_in_m: float  # straight final approach along the hanging keypoint's x axis
    max_release_offset_m: float  # ξ_0 may be this far from the hang (lifted / back)
    check_step_m: float  # largest motion of any probe point between checked poses
    probe_radius_m: float  # farthest probe point from the keypoint
    goal_bias: float  # share of tree samples drawn in the start region
    surface_bias: float  # share of tree samples drawn near the support's surface
    max_checks: int  # budget, in pose checks
    shortcut_steps: int  # shortcut attempts on the found path
    T: int  # waypoints the SKT is executed with (resampled)
    plane_bias: float = 0.0  # share of tree samples moved onto the threading plane
    route_bias: float = 0.0  # share of tree samples drawn near the arm's threading route


def _norm(v: np.ndarray) -> float:
    """``np.linalg.norm`` of a float vector, bit for bit (it is ``sqrt(v.dot(v))``), without its
    per-call overhead: the planner takes hundreds of thousands."""
    return math.sqrt(float(v.dot(v)))


def _unit(v: np.ndarray) -> np.ndarray:
    return v / _norm(v)


def _angle(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.arccos(np.clip(np.dot(a, b), -1.0, 1.0)))


def limit_direction(d: np.ndarray, prev: np.ndarray, max_turn: float) -> np.ndarray:
    """Unit direction closest to ``d`` within ``max_turn`` rad of ``prev`` (unit)."""
    d = _unit(np.asarray(d, float))
    if _angle(d, prev) > max_turn:
        axis = cross3(prev, d)
        if np.linalg.norm(axis) < 1e-9:  # opposite: turn about a horizontal axis
            axis = cross3(prev, (0.0, 0.0, 1.0))
            if np.linalg.norm(axis) < 1e-9:
                axis = np.array([0.0, 1.0, 0.0])
        axis = _unit(axis)
        d = prev * np.cos(max_turn) + cross3(axis, prev) * np.sin(max_turn)
    return _unit(d)


def transport(r: np.ndarray, new_x: np.ndarray) -> np.ndarray:
    """The frame ``r`` (3, 3) turned by the smallest rotation taking its x axis onto the unit
    ``new_x`` — one step of :func:`~skt_lib.geometry.skt.skt_frames`."""
    return minimal_rotation(r[:, 0], new_x, r[:, 1]) @ r


def exec_frames(points: np.ndarray) -> np.ndarray:
    """SKT frames ``(N, 4, 4)`` of the polyline ``points`` given in *execution* order."""
    return skt_frames(points[::-1])[::-1]


def exec_frames_kept(points: np.ndarray, old_frames: np.ndarray, m: int) -> np.ndarray:
    """:func:`exec_frames` of ``points`` whose hang side ``points[m:]`` is the last ``N − m``
    vertices of a path whose frames were ``old_frames``: frames are carried from the hang
    outward, so those of vertices ``m + 1 …`` are the old ones and only the rest are
    transported anew — with :func:`~skt_lib.geometry.skt.skt_frames`' own steps, so the
    result is bit for bit the full computation's (``tests/planning/test_many_skts.py``)."""
    n = len(points)
    if m >= n - 2 or m < 0:
        return exec_frames(points)
    head = points[: m + 2][::-1]  # the changed part, hang side first, with one kept vertex
    motion = head[:-1] - head[1:]
    motion = np.vstack([motion, motion[-1:]])
    norm = np.linalg.norm(motion, axis=1)
    if not np.all(norm >= 1e-12):
        return exec_frames(points)
    t = motion / norm[:, None]
    t[0] = old_frames[-(n - m - 1), :3, 0]  # the motion arriving at the first kept vertex
    y = np.empty_like(t)
    y[0] = old_frames[-(n - m - 1), :3, 1]
    for i in range(1, len(t)):  # skt_frames' double reflection, outward from the kept part
        r, v2 = y[i - 1], t[i] + t[i - 1]
        c2 = float(v2 @ v2)
        if c2 > 1e-24:
            r = r - (2.0 * float(v2 @ r) / c2) * v2
        r = r - float(r @ t[i]) * t[i]
        y[i] = r / _norm(r)
    out = np.empty((n, 4, 4))
    out[m + 1:] = old_frames[-(n - m - 1):]
    new = np.tile(np.eye(4), (m + 1, 1, 1))
    new[:, :3, :3] = np.stack([t[1:], y[1:], np.cross(t[1:], y[1:])], axis=2)[::-1]
    new[:, :3, 3] = points[: m + 1]
    out[: m + 1] = new
    return out


def _quat(r: np.ndarray) -> np.ndarray:
    """xyzw quaternion of a rotation matrix, without scipy's per-call overhead (Shepperd)."""
    t = r[0, 0] + r[1, 1] + r[2, 2]
    if t > 0.0:
        w = np.sqrt(1.0 + t) * 2.0
        q = [(r[2, 1] - r[1, 2]) / w, (r[0, 2] - r[2, 0]) / w, (r[1, 0] - r[0, 1]) / w, 0.25 * w]
    elif r[0, 0] > r[1, 1] and r[0, 0] > r[2, 2]:
        w = np.sqrt(1.0 + r[0, 0] - r[1, 1] - r[2, 2]) * 2.0
        q = [0.25 * w, (r[0, 1] + r[1, 0]) / w, (r[0, 2] + r[2, 0]) / w, (r[2, 1] - r[1, 2]) / w]
    elif r[1, 1] > r[2, 2]:
        w = np.sqrt(1.0 + r[1, 1] - r[0, 0] - r[2, 2]) * 2.0
        q = [(r[0, 1] + r[1, 0]) / w, 0.25 * w, (r[1, 2] + r[2, 1]) / w, (r[0, 2] - r[2, 0]) / w]
    else:
        w = np.sqrt(1.0 + r[2, 2] - r[0, 0] - r[1, 1]) * 2.0
        q = [(r[0, 2] + r[2, 0]) / w, (r[1, 2] + r[2, 1]) / w, 0.25 * w, (r[1, 0] - r[0, 1]) / w]
    q = np.asarray(q)
    return q / _norm(q)


def _slerp(q0: np.ndarray, q1: np.ndarray, u: np.ndarray) -> np.ndarray:
    """Quaternions ``(len(u), 4)`` on the short arc from ``q0`` to ``q1`` (xyzw)."""
    dot = float(np.dot(q0, q1))
    if dot < 0.0:
        q1, dot = -q1, -dot
    if dot > 0.9995:
        q = q0 + np.outer(u, q1 - q0)
    else:
        th = np.arccos(dot)
        q = (np.outer(np.sin((1 - u) * th), q0) + np.outer(np.sin(u * th), q1)) / np.sin(th)
    return q / np.linalg.norm(q, axis=1, keepdims=True)


class _Checker:
    """Counts pose checks against the budget; checks straight segments between two frames
    exactly as :func:`~skt_lib.geometry.skt.interpolate` executes them (linear
    position, slerp rotation, at most ``check_step_m`` of probe-point motion per pose)."""

    def __init__(self, collides: Callable[[np.ndarray, np.ndarray], bool], s: ThreadSettings):
        self.collides, self.s, self.n = collides, s, 0

    def frames(self, poses: np.ndarray) -> bool:
        """True when every pose ``(M, 4, 4)`` (keypoint frames, support frame) is clear."""
        for t in poses:
            self.n += 1
            if self.collides(t[:3, 3], _quat(t[:3, :3])):
                return False
        return True

    def segment(self, pa, pb, ra, rb, qa=None, qb=None) -> bool:
        """Straight motion ``pa → pb`` with the orientation slerped ``ra → rb`` (as executed),
        ``pb`` included, ``pa`` not; ``qa``, ``qb``: their :func:`_quat`, where known."""
        qa = _quat(ra) if qa is None else qa
        qb = _quat(rb) if qb is None else qb
        angle = 2.0 * np.arccos(min(1.0, abs(float(np.dot(qa, qb)))))
        n = max(1, int(np.ceil((_norm(pb - pa) + angle * self.s.probe_radius_m)
                               / self.s.check_step_m)))
        u = np.arange(1, n + 1) / n
        # all poses at once, as plain lists (the probe takes them a pose at a time)
        positions = (pa + np.outer(u, pb - pa)).tolist()
        quats = [qb.tolist()] * n if angle < 1e-9 else _slerp(qa, qb, u).tolist()
        collides = self.collides
        for k in range(n):
            self.n += 1
            if collides(positions[k], quats[k]):
                return False
        return True

    def path(self, points: np.ndarray, old: np.ndarray, old_frames: np.ndarray) -> np.ndarray | None:
        """Check the polyline ``points (N, 3)`` (execution order) as executed, where it differs
        from a path already checked: ``old (N,)`` gives each vertex's index in that path (−1:
        a new vertex) and ``old_frames`` that path's executed frames. A segment is checked
        when an end is new or its frame changed (transport carries a change outward). Returns
        the new frames ``(N, 4, 4)``, or ``None`` when a checked pose collides. Segments with
        a new end are checked first (the verdict does not depend on the order)."""
        tail = len(old_frames) - len(points) + np.arange(len(points))  # old index if kept
        kept = np.flatnonzero(old != tail)
        frames = exec_frames_kept(points, old_frames, int(kept[-1]) + 1 if len(kept) else 0)
        same = np.zeros(len(points), bool)
        known = old >= 0
        same[known] = np.all(np.abs(frames[known, :3, :3] - old_frames[old[known], :3, :3]) < 1e-9,
                             axis=(1, 2))
        if not same[0] and not self.frames(frames[:1]):
            return None
        todo = [k for k in range(len(points) - 1)
                if not (same[k] and same[k + 1] and old[k + 1] == old[k] + 1)]
        # new stretches first: a shortcut through the support fails there, before the rest
        # of the path (whose frames it rolled) is checked; the verdict is the same either way
        todo.sort(key=lambda k: old[k] >= 0 and old[k + 1] >= 0)
        quats: dict[int, np.ndarray] = {}  # consecutive segments share a frame

        def quat(k: int) -> np.ndarray:
            if k not in quats:
                quats[k] = _quat(frames[k][:3, :3])
            return quats[k]

        for k in todo:
            if not self.segment(points[k], points[k + 1], frames[k][:3, :3], frames[k + 1][:3, :3],
                                quat(k), quat(k + 1)):
                return None
        return frames


def plan_threading(goal: np.ndarray, in_start: Callable[[np.ndarray], bool],
                   sample_start: Callable[[np.random.Generator], np.ndarray],
                   lower: np.ndarray, upper: np.ndarray, collides: Callable[[np.ndarray], bool],
                   s: ThreadSettings, rng: np.random.Generator,
                   start_point: np.ndarray | None = None,
                   sample_near: Callable[[np.random.Generator], np.ndarray] | None = None,
                   sample_route: Callable[[np.random.Generator], np.ndarray] | None = None
                   ) -> tuple[np.ndarray, int]:
    """Keypoint positions ``(N, 3)``, ξ_0 (within ``max_release_offset_m`` of the hang) first,
    vertices at most ``step_m`` apart, whose execution (SKT frames) is clear for
    ``collides``; and the checks used.

    ``goal``: the hanging keypoint frame (4×4, support frame; its x axis is the threading
    direction). ``in_start(p)``: whether a keypoint position may start the SKT;
    ``sample_start(rng)``: a position in that region. ``collides(position, quat)``: the probe
    at a keypoint pose touches the support or wall. ``start_point``: the canonical start the
    path is extended to when it can be; ``sample_near(rng)``: a position near the support's
    surface (drawn with ``surface_bias``); ``sample_route(rng)``: a position near the arm's
    threading route (:mod:`skt_lib.planning.route`, drawn with ``route_bias``, never moved
    onto the threading plane). Raises :class:`ThreadingFailed`."""
    check = _Checker(collides, s)
    sampler = _Sampler(sample_start, sample_near, lower, upper, s,
                       threading_plane(goal) if s.plane_bias > 0 else None, sample_route)
    n_rejected = 0
    for lead, a0, r0 in _releases(goal[:3, 3], _unit(goal[:3, 0]), check, s):
        while True:  # fresh trees from this release until one survives resampling (one budget)
            n_before = check.n
            try:
                tree = _Tree(lead, a0, r0, lower, upper, check, s)
                leaf = tree.grow(in_start, sampler, rng, s.max_checks)
            except ThreadingFailed:
                if n_rejected:
                    raise ThreadingFailed(f"{n_rejected} path(s) collided once resampled to "
                                          f"T = {s.T}; budget spent", "resample_collision") from None
                raise
            if leaf is None:
                break  # stuck: next release
            dense = _read_out(tree, leaf, start_point, check, s, rng)
            if dense is not None:
                return dense, check.n
            n_rejected += 1
            if check.n == n_before:  # nothing new can come from this release
                break
    if n_rejected:
        raise ThreadingFailed(f"{n_rejected} path(s) collided once resampled to T = {s.T}",
                              "resample_collision")
    raise ThreadingFailed("the tree could not leave any clear release", "stuck")


def _read_out(tree: "_Tree", leaf: int, start_point, check: _Checker, s: ThreadSettings,
              rng: np.random.Generator) -> np.ndarray | None:
    """The SKT of ``leaf``: its chain to the root joined to ``start_point`` (when given),
    shortcut, resampled to ``T`` and checked once more as executed; dense, ξ_0 first, or
    ``None`` when the resampled execution collides."""
    turn = np.radians(s.max_turn_deg)
    path = tree.chain(leaf)
    frames = exec_frames(path)
    if start_point is not None:
        path, frames = _snap_start(path, frames, np.asarray(start_point, float), check, s, turn)
    path = _shortcut(path, frames, check, s, turn, rng)
    dense = densify(path, s.step_m)[::-1]  # ξ_0 first
    final = executed_path(resample(dense, s.T), s.check_step_m, s.probe_radius_m)
    return dense if check.frames(final) else None


#: Leaves of one tree of :func:`plan_threading_many` that may collide once resampled, in a
#: row, before a fresh tree grows (each further leaf costs only the tree's growth from where
#: it stands; a fresh tree pays the threading again).
MISSES_PER_TREE = 4
#: Leaves an SKT of :func:`plan_threading_many` joins to its own start before it joins the
#: next ones to SKT 0's (the region's centre): a start whose joined paths keep colliding once
#: resampled would otherwise spend the SKT's whole budget (measured on support_00001, 50
#: SKTs: 3 of them took 73k–150k checks, 30 s of the support's 31 s).
START_TRIES = 2
#: A further leaf of :func:`plan_threading_many` must come within this share of
#: ``max_checks`` (the first leaf has the whole budget: it threads the hang).
LEAF_BUDGET_SHARE = 0.1


def plan_threading_many(goal: np.ndarray, starts: np.ndarray,
                        in_start: Callable[[np.ndarray], bool],
                        sample_start: Callable[[np.random.Generator], np.ndarray],
                        lower: np.ndarray, upper: np.ndarray, collides: Callable,
                        s: ThreadSettings, rng: np.random.Generator,
                        sample_near: Callable | None = None,
                        sample_route: Callable | None = None):
    """``len(starts)`` SKTs from **one** tree (the arguments as :func:`plan_threading`'s),
    yielded one at a time as ``(dense SKT ξ_0 first | None, failure reason | None, pose checks
    used so far)``, SKT ``i`` joined to ``starts[i]``.

    Every SKT of a support ends at the same hang, and the costly part of a search is the
    threading from it — over an upturned tip, through a curl. So one tree is grown backward
    from the first release it can leave (as :func:`plan_threading`), and each SKT is read out
    of it: SKT ``i`` takes a leaf of its own (a node in the start region; leaves are never
    extended, so each is a distinct path), is joined to its own start ``starts[i]``, shortcut
    with the shared generator, resampled and checked as executed — every check of the
    per-SKT planner, none shared but the tree's. A further leaf is grown from the tree as it
    stands (within :data:`LEAF_BUDGET_SHARE` of the budget). A leaf whose resampled
    execution collides is replaced; after :data:`MISSES_PER_TREE` such leaves in a row (or a
    tree that gives no further leaf) the tree's trunk is the trouble (a curl whose
    resampling cuts a corner), and a fresh tree grows from the same release, as the per-SKT
    planner would. After :data:`START_TRIES` such leaves an SKT is joined to ``starts[0]``
    instead of its own start. Each SKT has the per-SKT planner's budget, ``max_checks`` pose checks
    (SKT 0's counted from the start, the tree included); spent, it fails as ``no_path`` or,
    where leaves were read out but collided once resampled, ``resample_collision``.

    With the same generator state and ``starts[0]`` as :func:`plan_threading`'s
    ``start_point``, SKT 0 is that planner's SKT (when its first path survives). SKT ``i``
    depends only on the SKTs before it, not on how many are asked for. Raises
    :class:`ThreadingFailed` (before the first yield) when no tree leaves any release: then
    no SKT exists."""
    starts = np.asarray(starts, float).reshape(-1, 3)
    check = _Checker(collides, s)
    sampler = _Sampler(sample_start, sample_near, lower, upper, s,
                       threading_plane(goal) if s.plane_bias > 0 else None, sample_route)
    for lead, a0, r0 in _releases(goal[:3, 3], _unit(goal[:3, 0]), check, s):
        tree = _Tree(lead, a0, r0, lower, upper, check, s)
        leaf = tree.grow(in_start, sampler, rng, s.max_checks)
        if leaf is not None:
            break
    else:
        raise ThreadingFailed("the tree could not leave any clear release", "stuck")
    leaf_budget = max(STUCK_CHECKS, int(LEAF_BUDGET_SHARE * s.max_checks))
    misses = 0  # the current tree's leaves that collided once resampled, in a row
    for i, start in enumerate(starts):
        end = s.max_checks if i == 0 else check.n + s.max_checks  # each SKT's budget
        dense, rejected, reason = None, 0, "no_path"
        while check.n < end:
            if leaf is None:
                fresh = misses >= MISSES_PER_TREE  # its trunk does not survive resampling
                if fresh:
                    tree, misses = _Tree(lead, a0, r0, lower, upper, check, s), 0
                try:
                    leaf = tree.grow(in_start, sampler, rng, min(
                        end, check.n + (s.max_checks if fresh else leaf_budget)), stuck=False)
                except ThreadingFailed:
                    misses = MISSES_PER_TREE  # this tree gives no more leaves: a fresh one
                    continue
            # a start whose joined paths keep colliding once resampled gives way to SKT 0's
            target = start if rejected < START_TRIES else starts[0]
            dense, leaf = _read_out(tree, leaf, target, check, s, rng), None
            if dense is not None:
                misses = 0
                break
            misses, rejected = misses + 1, rejected + 1
        if dense is None and rejected:
            reason = "resample_collision"
        yield dense, (None if dense is not None else reason), check.n


@dataclass(frozen=True)
class _Sampler:
    sample_start: Callable
    sample_near: Callable | None
    lower: np.ndarray
    upper: np.ndarray
    s: ThreadSettings
    plane: tuple[np.ndarray, np.ndarray] | None = None  # (point, unit normal)
    sample_route: Callable | None = None

    def __call__(self, rng: np.random.Generator) -> np.ndarray:
        q, on_route = self._draw(rng)
        if self.plane is not None and not on_route and rng.random() < self.s.plane_bias:
            point, normal = self.plane
            q = q - float(np.dot(q - point, normal)) * normal
        return q

    def _draw(self, rng: np.random.Generator) -> tuple[np.ndarray, bool]:
        u = rng.random()
        if u < self.s.goal_bias:
            return self.sample_start(rng), False
        u -= self.s.goal_bias
        if self.sample_near is not None and u < self.s.surface_bias:
            return self.sample_near(rng), False
        u -= self.s.surface_bias
        if self.sample_route is not None and u < self.s.route_bias:
            return self.sample_route(rng), True
        return rng.uniform(self.lower, self.upper), False


def threading_plane(goal: np.ndarray) -> tuple[np.ndarray, np.ndarray] | None:
    """``(point, unit normal)`` of the vertical plane through the hanging keypoint ``goal``
    (4×4, support frame, z up) that holds its x axis (the arrival direction); ``None`` when
    that axis is vertical (no such plane is defined)."""
    normal = np.cross(goal[:3, 0], [0.0, 0.0, 1.0])
    length = float(np.linalg.norm(normal))
    if length < 1e-6:
        return None
    return np.array(goal[:3, 3], float), normal / length


class _Tree:
    """The backward tree of one release: grown from the lead-in's far end, nodes at most
    ``step_m`` apart, each with the frame transported to it (module notes).

    Node v (not the root) stores ``dirs[v]``, the execution direction from v to its parent,
    and ``rots[v]``, the SKT frame at its parent when the path runs through v (x = ``dirs[v]``):
    the parent's own ``rots`` transported onto ``dirs[v]``. Positions live in a growing array
    (the nearest-node query is one vectorised distance); a node in the start region is a
    *leaf*: it ends a path and is never extended, so every later leaf is a path of its own."""

    def __init__(self, lead: np.ndarray, a0: np.ndarray, r0: np.ndarray, lower, upper,
                 check: _Checker, s: ThreadSettings):
        self.lower, self.upper, self.check, self.s = lower, upper, check, s
        self.turn = np.radians(s.max_turn_deg)
        self.n_lead = len(lead)
        self._pos = np.empty((max(1024, 2 * len(lead)), 3))
        self._pos[:len(lead)] = lead
        self.n = len(lead)
        self.dirs = [a0] * len(lead)
        self.rots = [r0] * len(lead)
        self.quats = [_quat(r0)] * len(lead)  # :func:`_quat` of each of ``rots``
        self.parent = [-1] + list(range(len(lead) - 1))
        self.first_free = len(lead) - 1  # the root and the lead-in's inside are not extended
        self._closed = np.zeros(len(self._pos), bool)  # leaves: never extended

    def grow(self, in_start, sampler, rng: np.random.Generator, max_checks: int,
             stuck: bool = True) -> int | None:
        """Add nodes until one lies in the start region; its index. ``None`` when the tree is
        stuck (``stuck`` and fewer than :data:`STUCK_NODES` nodes after :data:`STUCK_CHECKS`
        checks). Raises :class:`ThreadingFailed` when the checks reach ``max_checks``."""
        check, s = self.check, self.s
        if self.n == self.n_lead and in_start(self._pos[self.n - 1]):
            self._closed[self.n - 1] = True
            return self.n - 1
        n0 = check.n
        while True:
            if check.n >= max_checks:
                raise ThreadingFailed(f"no path within {max_checks} checks", "no_path")
            if stuck and check.n - n0 > STUCK_CHECKS and self.n - self.n_lead < STUCK_NODES:
                return None
            q = sampler(rng)
            dist = np.linalg.norm(self._pos[self.first_free:self.n] - q, axis=1)
            dist[self._closed[self.first_free:self.n]] = np.inf
            i = self.first_free + int(np.argmin(dist))
            if not np.isfinite(dist[i - self.first_free]) or dist[i - self.first_free] < 1e-9:
                continue
            p_i = self._pos[i]
            d = limit_direction(p_i - q, self.dirs[i], self.turn)  # execution direction new → i
            new = p_i - s.step_m * d
            if np.any(new < self.lower) or np.any(new > self.upper):
                continue
            rd = transport(self.rots[i], d)  # the frame at i (and at the new leaf) with this child
            qd = _quat(rd)
            if not check.segment(new, p_i, rd, rd, qd, qd):
                continue
            if self.parent[i] >= 0 and not check.segment(p_i, self._pos[self.parent[i]], rd,
                                                         self.rots[i], qd, self.quats[i]):
                continue
            v = self._add(new, d, rd, qd, i)
            if in_start(new):
                self._closed[v] = True
                return v

    def _add(self, p: np.ndarray, d: np.ndarray, r: np.ndarray, q: np.ndarray, parent: int) -> int:
        if self.n == len(self._pos):
            self._pos = np.concatenate([self._pos, np.empty_like(self._pos)])
            self._closed = np.concatenate([self._closed, np.zeros(len(self._closed), bool)])
        self._pos[self.n] = p
        self.dirs.append(d)
        self.rots.append(r)
        self.quats.append(q)
        self.parent.append(parent)
        self.n += 1
        return self.n - 1

    def chain(self, leaf: int) -> np.ndarray:
        """Positions from ``leaf`` to the root (execution order: start … ξ_0)."""
        chain = [leaf]
        while self.parent[chain[-1]] >= 0:
            chain.append(self.parent[chain[-1]])
        return self._pos[chain].copy()


#: Arrival directions tried at the release, as (pitch, yaw) offsets in degrees from the
#: hanging keypoint's x (negative pitch: arriving from above), nearest first.
ARRIVAL_OFFSETS_DEG = sorted(((p, y) for p in (0, -15, 15, -30, 30, -45, -60, -75)
                              for y in (0, -15, 15, -30, 30)), key=lambda o: (np.hypot(*o), o))


def arrival_directions(a0: np.ndarray) -> list[np.ndarray]:
    """Unit arrival directions around ``a0`` (:data:`ARRIVAL_OFFSETS_DEG`), ``a0`` first."""
    side = np.cross([0.0, 0.0, 1.0], a0)
    side = side / np.linalg.norm(side) if np.linalg.norm(side) > 1e-9 else np.array([0.0, 1.0, 0.0])
    up = np.cross(a0, side)  # a0's "up": pitch turns a0 toward it
    out = []
    for pitch, yaw in ARRIVAL_OFFSETS_DEG:
        p, y = np.radians(pitch), np.radians(yaw)
        d = np.cos(p) * (np.cos(y) * a0 + np.sin(y) * side) + np.sin(p) * up
        out.append(_unit(d))
    return out


def release_offsets(max_offset_m: float) -> tuple[list[tuple[float, float]], list[tuple[float, float]]]:
    """``(lift, back)`` offsets (m) of the release from the hang, ``hypot(lift, back) ≤
    max_offset_m``, in two rounds: lifts alone in :data:`LIFT_STEP_M` steps, then every other
    point of a :data:`RELEASE_STEP_M` grid, nearest the hang first (ties: less back first).
    Every arrival direction gets the first round before any gets the second: where a lift
    fits, it keeps more room for the tree (trying a 3 mm lift before the 4 mm one left a tall
    upturned tip unthreaded on 6 of 8 seeds)."""
    lifts = [(i * LIFT_STEP_M, 0.0) for i in range(int(np.floor(max_offset_m / LIFT_STEP_M + 1e-9)) + 1)]
    n = int(np.floor(max_offset_m / RELEASE_STEP_M + 1e-9))
    grid = [(i * RELEASE_STEP_M, j * RELEASE_STEP_M) for i in range(n + 1) for j in range(n + 1)
            if np.hypot(i, j) * RELEASE_STEP_M <= max_offset_m + 1e-12]
    rest = [o for o in grid if not any(np.allclose(o, q, rtol=0.0, atol=1e-12) for q in lifts)]
    return lifts, sorted(rest, key=lambda o: (np.hypot(*o), o[1], o[0]))


def _releases(hang: np.ndarray, a0: np.ndarray, check: _Checker, s: ThreadSettings):
    """Candidate straight lead-ins into the release ξ_0, as ``(lead (n + 1, 3) ξ_0 first,
    arrival direction, its anchor frame)``: ξ_0 at the hanging keypoint or lifted above it,
    then (second round) offset from it on a finer grid, lifted and/or moved back along the
    arrival (:func:`release_offsets`; at most ``max_release_offset_m``, never below the hang);
    in each round arriving along the hanging keypoint's x, then along directions turned from
    it (:func:`arrival_directions`: where an upturned part stands in front of the hang the
    object must come down into it); where the probe at the anchor frame clears the whole
    lead-in. The anchor is the rule's frame of the arrival — the hanging orientation the SKT
    frames give ξ_0. A tree stuck at one release tries the next."""
    n = max(1, int(np.ceil(s.lead_in_m / s.step_m)))
    found = False
    for offsets in release_offsets(s.max_release_offset_m):
        for d in arrival_directions(a0):
            try:
                r0 = skt_rotation(d)
            except ValueError:  # vertical: the rule gives no anchor
                continue
            for lift, back in offsets:
                p0 = hang + [0.0, 0.0, lift] - back * d
                if p0[2] < hang[2] - 1e-12:  # never released below the hang
                    continue
                lead = p0 - np.outer(np.arange(n + 1) * s.lead_in_m / n, d)
                if check.frames(_frame(lead[-1], r0)[None]) and check.segment(lead[-1], p0, r0, r0):
                    found = True
                    yield lead, d, r0
    if not found:
        raise ThreadingFailed("no clear straight lead-in at the hang or near it",
                              "lead_in_blocked")


def _frame(p: np.ndarray, r: np.ndarray) -> np.ndarray:
    t = np.eye(4)
    t[:3, :3], t[:3, 3] = r, p
    return t


def densify(points: np.ndarray, step: float) -> np.ndarray:
    """The polyline with vertices inserted so that none are more than ``step`` apart."""
    out = [points[:1]]
    for a, b in zip(points[:-1], points[1:]):
        n = max(1, int(np.ceil(np.linalg.norm(b - a) / step)))
        out.append(a + np.outer(np.arange(1, n + 1) / n, b - a))
    return np.concatenate(out)


def _turns_ok(points: np.ndarray, lo: int, hi: int, turn: float) -> bool:
    """Turn limit at every vertex of ``points`` between segments ``lo`` and ``hi``."""
    seg = np.diff(points, axis=0)
    seg = seg / np.linalg.norm(seg, axis=1, keepdims=True)
    lo, hi = max(lo - 1, 0), min(hi, len(seg) - 1)
    if hi <= lo:
        return True
    cos = np.sum(seg[lo:hi] * seg[lo + 1:hi + 1], axis=1)
    return bool(np.all(np.arccos(np.clip(cos, -1.0, 1.0)) <= turn + 1e-9))


def _snap_start(path: np.ndarray, frames: np.ndarray, start: np.ndarray, check: _Checker,
                s: ThreadSettings, turn: float) -> tuple[np.ndarray, np.ndarray]:
    """``path`` (execution order) begun at ``start`` instead: a straight stretch from
    ``start`` to its vertex k replaces the vertices before k, for the smallest k (over the
    first half of the path) where the stretch keeps the turn limit and its execution (with
    the frames it changes) is clear; otherwise ``path`` unchanged. With its frames."""
    if np.linalg.norm(path[0] - start) < 1e-9:
        return path, frames
    heads = ((k, densify(np.stack([start, path[k]]), s.step_m)[:-1])
             for k in range(max(1, len(path) // 2)))
    steered = _steer(start, path, s.step_m, turn)
    for k, head in [*heads, *([(0, steered)] if steered is not None else [])]:
        cand = np.concatenate([head, path[k:]])
        if not _turns_ok(cand, 0, len(head) + 1, turn):
            continue
        old = np.concatenate([np.full(len(head), -1), np.arange(k, len(path))])
        new_frames = check.path(cand, old, frames)
        if new_frames is not None:
            return cand, new_frames
    return path, frames


def _steer(start: np.ndarray, path: np.ndarray, step: float, turn: float,
           max_edges: int = 60) -> np.ndarray | None:
    """Vertices from ``start`` up to (not including) ``path[0]`` (execution order) that turn
    at most ``turn`` per edge: grown backward from ``path[0]``, each edge turned toward
    ``start`` as far as the limit allows, until ``start`` is one edge away; ``None`` when it
    does not get there within ``max_edges``."""
    pts, nxt = [path[0]], _unit(path[1] - path[0])
    for _ in range(max_edges):
        to_start = pts[-1] - start
        if np.linalg.norm(to_start) <= step:
            if _angle(_unit(to_start), nxt) <= turn + 1e-9:
                return densify(np.stack([start, *pts[::-1]]), step)[:-1]
            return None
        nxt = limit_direction(to_start, nxt, turn)
        pts.append(pts[-1] - step * nxt)
    return None


#: A stretch whose vertices lie this close to the line through its ends is straight (m).
STRAIGHT_TOL_M = 1e-9


def _straight(stretch: np.ndarray) -> bool:
    """Whether every vertex of ``stretch (n, 3)`` lies on the segment between its ends."""
    a, b = stretch[0], stretch[-1]
    ab = b - a
    length = float(np.linalg.norm(ab))
    if length < STRAIGHT_TOL_M:
        return False
    rel = stretch[1:-1] - a
    along = rel @ ab / length
    off = np.linalg.norm(rel - np.outer(along / length, ab), axis=1)
    return bool(np.all(off <= STRAIGHT_TOL_M) and np.all(along >= 0.0) and np.all(along <= length))


def _shortcut(path: np.ndarray, frames: np.ndarray, check: _Checker, s: ThreadSettings,
              turn: float, rng: np.random.Generator) -> np.ndarray:
    """Seeded shortcutting of an execution-ordered path; the final lead-in is kept straight.
    A straight replacement between vertices ``i`` and ``j`` is kept only when it respects the
    turn limit and its execution is clear wherever its frames change; a stretch that is
    straight already is left as it is (replacing it would only re-space its vertices, at the
    price of re-checking it)."""
    n_keep = max(1, int(np.ceil(s.lead_in_m / s.step_m)))
    for _ in range(s.shortcut_steps):
        last = len(path) - 1 - n_keep  # vertices after this belong to the lead-in
        if last < 2:
            break
        i, j = sorted(rng.choice(last + 1, size=2, replace=False))
        if j - i < 2 or _straight(path[i:j + 1]):
            continue  # already straight: the shortcut could only move vertices along it
        mid = densify(path[[i, j]], s.step_m)[1:-1]
        cand = np.concatenate([path[: i + 1], mid, path[j:]])
        if not _turns_ok(cand, i, i + len(mid) + 2, turn):
            continue
        old = np.concatenate([np.arange(i + 1), np.full(len(mid), -1), np.arange(j, len(path))])
        new_frames = check.path(cand, old, frames)
        if new_frames is not None:
            path, frames = cand, new_frames
    return path
