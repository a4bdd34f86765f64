"""From a tree leaf to an SKT, for the threading planner (:mod:`skt_lib.planning.threading`):
:func:`read_out` takes a leaf's chain to the root, joins it straight to the canonical start
where that keeps the turn limit and is clear (:func:`_snap_start`, :func:`_steer`), shortcuts
it (random, seeded; a shortcut rolls the frames of everything before it, so every segment
whose frames change is re-checked: :func:`_shortcut`), resamples it to the evaluated ``T``
waypoints and checks it once more as executed at that resolution. :func:`densify` is the
polyline resampling both use (and :mod:`skt_lib.planning.skts` too)."""

import numpy as np

from skt_lib.geometry.skt import executed_path, resample
from skt_lib.planning.checker import Checker
from skt_lib.planning.frames import angle, exec_frames, limit_direction, unit
from skt_lib.planning.thread_settings import ThreadSettings
from skt_lib.planning.tree import Tree


def read_out(tree: Tree, leaf: int, start_point, check: Checker, s: ThreadSettings,
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


def _snap_start(path: np.ndarray, frames: np.ndarray, start: np.ndarray, check: Checker,
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
    pts, nxt = [path[0]], unit(path[1] - path[0])
    for _ in range(max_edges):
        to_start = pts[-1] - start
        if np.linalg.norm(to_start) <= step:
            if angle(unit(to_start), nxt) <= turn + 1e-9:
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


def _shortcut(path: np.ndarray, frames: np.ndarray, check: Checker, s: ThreadSettings,
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
