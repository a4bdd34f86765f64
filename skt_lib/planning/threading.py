"""Threading planner: SKTs that are collision-free *as executed*.

An SKT is executed with the frames the SKT rule gives its positions (x = direction of motion,
y = x × g, z = x × y; :func:`skt_lib.planning.trajectory.executed_path`), so the object's
orientation is tied to the direction it moves — it is threaded along the path like a ring
along a wire. Planning in SE(3) and keeping only the positions (what the first version did)
certified poses that were never executed: 80 % of those paths penetrated the support when
replayed with rule frames. This planner searches keypoint positions only, with every pose
checked at exactly the frame execution will give it:

- a tree grows backward from the hang ξ_0 with edges of ``step_m``; the first ``lead_in_m``
  is a straight line along the hanging keypoint's x axis, so the object arrives along its
  threading direction and ends at its hanging orientation, not pitched by the last motion;
- an edge may turn the motion direction by at most ``max_turn_deg`` from the next edge and
  pitch it at most ``max_pitch_deg`` from horizontal (the rule is undefined for vertical
  motion and a steep pitch tips the object over);
- the release ξ_0 is the hanging keypoint, or, where an object of the probe does not fit
  there (a mug's body against the wall, a narrow aperture on a thick arm), the first clear
  point set back along the approach (≤ ``max_setback_m``) and lifted (≤ ``max_lift_m``):
  released there, the object slides or drops into the hang;
- every pose is checked with the *probe*: the reference object and every training object,
  each placed at its own keypoint frame, against the support and the wall with a clearance.
  The frame a pose gets depends on the edge before it (the rule uses the motion *arriving*
  at a waypoint, and execution slerps between waypoint frames), so adding a child re-checks
  its parent's edge with the orientation that child gives it;
- when a node reaches the start region, the path is extended straight to the canonical
  start (when given: the region's centre) where that stretch keeps the limits and is clear,
  so SKTs of one support start at one point and differ only where the support makes them;
  then it is shortcut (random, seeded, each candidate
  checked as executed), resampled to the evaluated ``T`` waypoints, and checked once more as
  executed at that resolution; a path that fails there is dropped and a fresh tree grows
  (the same budget). What passes is what ``sim_eval`` executes.

Deterministic: the caller's generator drives every sample; the budget is counted in checks.
"""

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from skt_lib.errors import ItemFailure
from skt_lib.geometry.se3 import skt_rotation
from skt_lib.planning.trajectory import arc_length, executed_path, resample, skt_frames


SETBACK_STEP_M = 0.005
LIFT_STEP_M = 0.002
#: A tree that has added fewer than STUCK_NODES nodes after STUCK_CHECKS checks is stuck at
#: its release: the next release candidate is tried.
STUCK_CHECKS, STUCK_NODES = 1500, 3


class ThreadingFailed(ItemFailure):
    reason = "no_path"


@dataclass(frozen=True)
class ThreadSettings:
    step_m: float  # tree edge length
    max_turn_deg: float  # largest change of motion direction between consecutive edges
    max_pitch_deg: float  # largest angle of a motion direction from horizontal
    lead_in_m: float  # straight final approach along the hanging keypoint's x axis
    max_setback_m: float  # ξ_0 may stop this far short of the hang, back along the approach
    max_lift_m: float  # … and this far above it
    check_step_m: float  # largest motion of any probe point between checked poses
    probe_radius_m: float  # farthest probe point from the keypoint
    goal_bias: float  # share of tree samples drawn in the start region
    max_checks: int  # budget, in pose checks
    shortcut_steps: int  # shortcut attempts on the found path
    T: int  # waypoints the SKT is executed with (resampled)


def _unit(v: np.ndarray) -> np.ndarray:
    return v / np.linalg.norm(v)


def _angle(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.arccos(np.clip(np.dot(a, b), -1.0, 1.0)))


def limit_direction(d: np.ndarray, prev: np.ndarray, max_turn: float, max_pitch: float) -> np.ndarray:
    """Unit direction closest to ``d`` within ``max_turn`` rad of ``prev`` and ``max_pitch``
    rad of horizontal (both unit vectors; ``prev`` must satisfy the pitch limit)."""
    d = _unit(np.asarray(d, float))
    a = _angle(d, prev)
    if a > max_turn:
        axis = np.cross(prev, d)
        if np.linalg.norm(axis) < 1e-9:  # opposite: turn about a horizontal axis
            axis = np.cross(prev, [0.0, 0.0, 1.0])
            if np.linalg.norm(axis) < 1e-9:
                axis = np.array([0.0, 1.0, 0.0])
        axis = _unit(axis)
        d = prev * np.cos(max_turn) + np.cross(axis, prev) * np.sin(max_turn)
    pitch = np.arcsin(np.clip(d[2], -1.0, 1.0))
    if abs(pitch) > max_pitch:
        h = d[:2] if np.linalg.norm(d[:2]) > 1e-9 else prev[:2]
        h = _unit(h) * np.cos(max_pitch)
        d = np.array([h[0], h[1], np.sign(pitch) * np.sin(max_pitch)])
    return _unit(d)


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
    return q / np.linalg.norm(q)


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
    exactly as :func:`~skt_lib.planning.trajectory.interpolate` executes them (linear
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

    def segment(self, pa, pb, ra, rb) -> bool:
        """Straight motion ``pa → pb`` with the orientation slerped ``ra → rb`` (as executed),
        ``pb`` included, ``pa`` not."""
        qa, qb = _quat(ra), _quat(rb)
        angle = 2.0 * np.arccos(min(1.0, abs(float(np.dot(qa, qb)))))
        n = max(1, int(np.ceil((np.linalg.norm(pb - pa) + angle * self.s.probe_radius_m)
                               / self.s.check_step_m)))
        u = np.arange(1, n + 1) / n
        quats = np.tile(qb, (n, 1)) if angle < 1e-9 else _slerp(qa, qb, u)
        for k in range(n):
            self.n += 1
            if self.collides(pa + u[k] * (pb - pa), quats[k]):
                return False
        return True

    def path(self, points: np.ndarray, lo: int = 0, hi: int | None = None) -> bool:
        """The polyline ``points (N, 3)`` in *execution* order, executed with rule frames:
        segments ``lo..hi`` (exclusive) checked, the first pose included when ``lo == 0``."""
        frames = skt_frames(points[::-1])[::-1]  # rule frames, execution order
        hi = len(points) - 1 if hi is None else hi
        if lo == 0 and not self.frames(frames[:1]):
            return False
        return all(self.segment(points[k], points[k + 1], frames[k][:3, :3], frames[k + 1][:3, :3])
                   for k in range(max(lo, 0), min(hi, len(points) - 1)))


def plan_threading(goal: np.ndarray, in_start: Callable[[np.ndarray], bool],
                   sample_start: Callable[[np.random.Generator], np.ndarray],
                   lower: np.ndarray, upper: np.ndarray, collides: Callable[[np.ndarray], bool],
                   s: ThreadSettings, rng: np.random.Generator,
                   start_point: np.ndarray | None = None) -> tuple[np.ndarray, int]:
    """Keypoint positions ``(N, 3)``, ξ_0 (the hang) first, vertices at most ``step_m`` apart,
    whose execution (rule frames) is clear for ``collides``; and the checks used.

    ``goal``: the hanging keypoint frame (4×4, support frame; its x axis is the threading
    direction). ``in_start(p)``: whether a keypoint position may start the SKT;
    ``sample_start(rng)``: a position in that region. ``collides(frame)``: the probe at a
    keypoint frame touches the support or wall. ``start_point``: the canonical start the
    path is extended to when it can be (see the module notes). Raises :class:`ThreadingFailed`."""
    turn, pitch = np.radians(s.max_turn_deg), np.radians(s.max_pitch_deg)
    check = _Checker(collides, s)
    a0 = limit_direction(goal[:3, 0], goal[:3, 0], np.pi, pitch)
    r0 = skt_rotation(a0)
    n_rejected = 0
    for lead in _releases(goal[:3, 3], a0, r0, check, s):
        while True:  # fresh trees from this release until one survives resampling (one budget)
            n_before = check.n
            try:
                path = _grow(lead, a0, in_start, sample_start, lower, upper, check, s, rng)
            except ThreadingFailed:
                if n_rejected:
                    raise ThreadingFailed(f"{n_rejected} path(s) collided once resampled to "
                                          f"T = {s.T}; budget spent", "resample_collision") from None
                raise
            if path is None:
                break  # stuck: next release
            if start_point is not None:
                path = _snap_start(path, np.asarray(start_point, float), check, s, turn, pitch)
            path = _shortcut(path, check, s, turn, pitch, rng)
            dense = densify(path, s.step_m)[::-1]  # ξ_0 first
            final = executed_path(resample(dense, s.T), s.check_step_m, s.probe_radius_m)
            if check.frames(final):
                return dense, check.n
            n_rejected += 1
            if check.n == n_before:  # nothing new can come from this release
                break
    if n_rejected:
        raise ThreadingFailed(f"{n_rejected} path(s) collided once resampled to T = {s.T}",
                              "resample_collision")
    raise ThreadingFailed("the tree could not leave any clear release", "stuck")


def _grow(lead: np.ndarray, a0: np.ndarray, in_start, sample_start, lower, upper,
          check: _Checker, s: ThreadSettings, rng: np.random.Generator) -> np.ndarray | None:
    """Grow the tree backward from the lead-in's far end until a node lies in the start
    region; the chain to it in execution order (start … ξ_0), or ``None`` when the tree is
    stuck (fewer than :data:`STUCK_NODES` nodes after :data:`STUCK_CHECKS` checks)."""
    turn, pitch = np.radians(s.max_turn_deg), np.radians(s.max_pitch_deg)
    pos = list(lead)
    dirs = [a0] * len(lead)  # execution direction from the node to its parent
    parent = [-1] + list(range(len(lead) - 1))
    first_free = len(lead) - 1  # the root and the lead-in's inside are not extended
    leaf = len(lead) - 1 if in_start(lead[-1]) else None
    n0 = check.n
    while leaf is None:
        if check.n >= s.max_checks:
            raise ThreadingFailed(f"no path within {s.max_checks} checks", "no_path")
        if check.n - n0 > STUCK_CHECKS and len(pos) - len(lead) < STUCK_NODES:
            return None
        q = sample_start(rng) if rng.random() < s.goal_bias else rng.uniform(lower, upper)
        cand = np.asarray(pos[first_free:])
        i = first_free + int(np.argmin(np.linalg.norm(cand - q, axis=1)))
        if np.linalg.norm(q - pos[i]) < 1e-9:
            continue
        d = limit_direction(pos[i] - q, dirs[i], turn, pitch)  # execution direction new → i
        new = pos[i] - s.step_m * d
        if np.any(new < lower) or np.any(new > upper):
            continue
        rd = skt_rotation(d)
        if not check.segment(new, pos[i], rd, rd):
            continue
        if parent[i] >= 0 and not check.segment(pos[i], pos[parent[i]], rd, skt_rotation(dirs[i])):
            continue
        pos.append(new)
        dirs.append(d)
        parent.append(i)
        if in_start(new):
            leaf = len(pos) - 1
    chain = [leaf]
    while parent[chain[-1]] >= 0:
        chain.append(parent[chain[-1]])
    return np.asarray([pos[k] for k in chain])


def _releases(hang: np.ndarray, a0: np.ndarray, r0: np.ndarray, check: _Checker,
             s: ThreadSettings) -> np.ndarray:
    """Candidate straight lead-ins ``(n + 1, 3)``, ξ_0 first, along ``a0`` into the release
    ξ_0, nearest first: the hanging keypoint, or points set back along the approach (``SETBACK_STEP_M``
    steps, ≤ ``max_setback_m``) and lifted (``LIFT_STEP_M`` steps, ≤ ``max_lift_m``) — the
    smallest offset first — where the probe at the rule frame clears the whole lead-in. A
    tree stuck at one release tries the next (a larger lift leaves room to turn)."""
    n = max(1, int(np.ceil(s.lead_in_m / s.step_m)))
    found = False
    offsets = [(b, h) for b in np.arange(0.0, s.max_setback_m + 1e-9, SETBACK_STEP_M)
               for h in np.arange(0.0, s.max_lift_m + 1e-9, LIFT_STEP_M)]
    for back, lift in sorted(offsets, key=lambda o: (np.hypot(*o), o)):
        p0 = hang - back * a0 + [0.0, 0.0, lift]
        lead = p0 - np.outer(np.arange(n + 1) * s.lead_in_m / n, a0)
        if check.frames(_frame(lead[-1], r0)[None]) and check.segment(lead[-1], p0, r0, r0):
            found = True
            yield lead
    if not found:
        raise ThreadingFailed("no clear straight lead-in within the set-back and lift ranges",
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


def _turns_ok(points: np.ndarray, lo: int, hi: int, turn: float, pitch: float) -> bool:
    """Turn and pitch limits at every vertex/segment of ``points`` between ``lo`` and ``hi``."""
    seg = np.diff(points, axis=0)
    seg = seg / np.linalg.norm(seg, axis=1, keepdims=True)
    lo, hi = max(lo, 0), min(hi, len(seg))
    if np.any(np.abs(np.arcsin(np.clip(seg[lo:hi, 2], -1, 1))) > pitch + 1e-9):
        return False
    return all(_angle(seg[k], seg[k + 1]) <= turn + 1e-9 for k in range(max(lo - 1, 0), min(hi, len(seg) - 1)))


def _snap_start(path: np.ndarray, start: np.ndarray, check: _Checker, s: ThreadSettings,
                turn: float, pitch: float) -> np.ndarray:
    """``path`` (execution order) with a straight stretch from ``start`` to its first vertex
    prepended, when the stretch keeps the turn and pitch limits and its execution (with the
    first vertex's frame it changes) is clear; otherwise ``path`` unchanged."""
    if np.linalg.norm(path[0] - start) < 1e-9:
        return path
    head = densify(np.stack([start, path[0]]), s.step_m)[:-1]
    cand = np.concatenate([head, path])
    hi = len(head) + 2  # the new stretch and the old first edge, whose start frame changes
    if _turns_ok(cand, 0, hi, turn, pitch) and check.path(cand, 0, hi):
        return cand
    return path


def _shortcut(path: np.ndarray, check: _Checker, s: ThreadSettings, turn: float, pitch: float,
              rng: np.random.Generator) -> np.ndarray:
    """Seeded shortcutting of an execution-ordered path; the final lead-in is kept straight.
    A straight replacement between vertices ``i`` and ``j`` is kept only when it respects the
    turn and pitch limits and its execution (with the neighbouring frames it changes) is clear."""
    n_keep = max(1, int(np.ceil(s.lead_in_m / s.step_m)))
    for _ in range(s.shortcut_steps):
        last = len(path) - 1 - n_keep  # vertices after this belong to the lead-in
        if last < 2:
            break
        i, j = sorted(rng.choice(last + 1, size=2, replace=False))
        if j - i < 2:
            continue
        mid = densify(path[[i, j]], s.step_m)[1:-1]
        cand = np.concatenate([path[: i + 1], mid, path[j:]])
        k_hi = i + 1 + len(mid) + 1
        if not _turns_ok(cand, i - 1, k_hi + 1, turn, pitch):
            continue
        if check.path(cand, max(i - 1, 0), k_hi + 1):
            path = cand
    return path


def path_length(points: np.ndarray) -> float:
    return float(arc_length(points)[-1])
