"""The SKT contract (docs/design.md §3): keypoint trajectories, their frames, resampling and the
path as executed. Planning, simulation, learning and the command line all use this module
and nothing else for it.

An SKT is ``T`` waypoints ξ_0..ξ_{T-1} in the support frame, ξ_0 at the hanging pose;
execution runs ξ_{T-1} → ξ_0. Positions are ``(T, 3)`` float64 metres; frames ``(T, 4, 4)``
keypoint poses in the support frame; quaternions, where any appear, xyzw.

**Frames: rotation-minimizing, anchored at the hang.** The x axis of waypoint i is the unit
motion *arriving* at it (from ξ_{i+1} to ξ_i; ξ_{T-1} takes the motion leaving it). The roll
about x is not fixed by gravity (the paper's rule, x = motion, y = x × g, is undefined for
vertical motion and flips 180° where the horizontal motion changes sign), it is carried
along the path: the frame at ξ_0 is the rule's frame of the motion arriving at the hang (the
hanging orientation), and each next frame outward is the previous one turned by the
smallest rotation taking the previous x onto the next (discrete parallel transport; computed
by double reflection, Wang et al. 2008, which is that rotation exactly when the tangents are
the segment directions). Where the motion stays horizontal, or in one vertical plane without
crossing the vertical, these frames equal the rule's; on a helix they differ by the path's
holonomy. Where the rule is undefined at the hang (vertical arrival) the anchor is the rule
frame at the first waypoint outward where it is defined, and the frames are transported both
ways from there. Zero-length segments take the nearest defined motion (ties toward ξ_0).

**Resampling** spaces waypoints by arc length *and* turning: a step's length is the keypoint's
travel plus the object's rotation (rad) times :data:`TURN_RADIUS_M`, so a tight bend — where
the keypoint barely moves while the object turns — gets waypoints in proportion to its turn.
"""

import math

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from skt_lib.geometry.se3 import GRAVITY_DIR, transform_points

#: Reference radius (m) at which the object's rotation counts as distance when an SKT is
#: resampled: a 90° turn weighs like 4.7 cm of travel (about the reference ring's reach).
TURN_RADIUS_M = 0.03
_EPS_LEN = 1e-12  # shorter segments have no direction
_EPS_VERTICAL = 1e-6  # |x × g| below this: the rule is undefined


def keypoint_positions(poses: np.ndarray, keypoint: np.ndarray) -> np.ndarray:
    """Keypoint positions ``(N, 3)`` for object poses ``(N, 4, 4)`` and an object-frame
    keypoint ``(3,)``."""
    poses = np.asarray(poses)
    return np.einsum("nij,j->ni", poses[:, :3, :3], keypoint) + poses[:, :3, 3]


def arc_length(positions: np.ndarray) -> np.ndarray:
    """Cumulative arc length ``(N,)`` starting at 0."""
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(positions, axis=0), axis=1))])


def _as_positions(positions) -> np.ndarray:
    positions = np.asarray(positions, dtype=np.float64)
    if positions.ndim != 2 or positions.shape[1] != 3 or len(positions) < 2:
        raise ValueError(f"positions: expected (N>=2, 3), got {positions.shape}")
    return positions


def motion_directions(positions: np.ndarray) -> np.ndarray:
    """Unit motion arriving at each waypoint ``(T, 3)`` (ξ_{i+1} → ξ_i; the last waypoint
    takes the motion leaving it). Zero-length segments take the nearest defined direction
    (ties toward ξ_0). Raises ``ValueError`` when no segment has a length."""
    positions = _as_positions(positions)
    motion = positions[:-1] - positions[1:]
    motion = np.vstack([motion, motion[-1:]])
    norm = np.linalg.norm(motion, axis=1)
    known = np.isfinite(norm) & (norm >= _EPS_LEN)
    if not known.any():
        raise ValueError("positions: zero-length trajectory; SKT frames are undefined")
    k = np.flatnonzero(known)
    nearest = k[np.abs(k[None, :] - np.arange(len(positions))[:, None]).argmin(1)]
    return motion[nearest] / norm[nearest][:, None]


def rule_frames(positions: np.ndarray) -> np.ndarray:
    """The paper's per-waypoint rule ``(T, 4, 4)`` (x = motion arriving, y = x × g,
    z = x × y), ``NaN`` rotations where it is undefined (vertical motion). Kept to anchor
    :func:`skt_frames` and to compare against it; no method executes it."""
    positions = _as_positions(positions)
    x = motion_directions(positions)
    y = np.cross(x, GRAVITY_DIR)
    y_norm = np.linalg.norm(y, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        y = np.where((y_norm >= _EPS_VERTICAL)[:, None], y / y_norm[:, None], np.nan)
    out = np.tile(np.eye(4), (len(positions), 1, 1))
    out[:, :3, :3] = np.stack([x, y, np.cross(x, y)], axis=2)
    out[:, :3, 3] = positions
    return out


def _anchor(positions: np.ndarray) -> tuple[int, np.ndarray]:
    """(index, rotation): the first waypoint from the hang where the rule is defined."""
    rules = rule_frames(positions)
    defined = np.flatnonzero(np.isfinite(rules[:, 0, 1]))
    if not len(defined):
        raise ValueError("positions: every segment is vertical; SKT rotations are undefined")
    return int(defined[0]), rules[defined[0], :3, :3]


def skt_frames(positions: np.ndarray) -> np.ndarray:
    """SE(3) waypoints ``(T, 4, 4)`` (support frame) for SKT positions ``(T, 3)``, ξ_0 (the
    hang) first: rotation-minimizing frames anchored at the hang (module notes), by double
    reflection of the y axis from waypoint to waypoint (the segment directions are the
    tangents, so the first reflection's plane is the one ⊥ the previous motion)."""
    positions = _as_positions(positions)
    t = motion_directions(positions)
    k, r_anchor = _anchor(positions)
    y = np.empty_like(t)
    y[k] = r_anchor[:, 1]
    for step in (1, -1):  # outward from the anchor (toward ξ_{T-1}), then back to ξ_0
        stop = len(t) if step == 1 else -1
        for i in range(k + step, stop, step):
            # reflection 1 (across the plane ⊥ the previous motion) leaves y as it is and
            # turns the previous x to its opposite; reflection 2, across the plane ⊥ the sum
            # of both motions, takes that onto the next x: together the minimal rotation
            r, v2 = y[i - step], t[i] + t[i - step]
            c2 = float(v2 @ v2)
            if c2 > 1e-24:  # (opposite motions: the half turn about y)
                r = r - (2.0 * float(v2 @ r) / c2) * v2
            r = r - float(r @ t[i]) * t[i]
            y[i] = r / np.linalg.norm(r)
    out = np.tile(np.eye(4), (len(positions), 1, 1))
    out[:, :3, :3] = np.stack([t, y, np.cross(t, y)], axis=2)
    out[:, :3, 3] = positions
    return out


def cross3(a, b) -> np.ndarray:
    """``np.cross`` of two 3-vectors without its per-call overhead (tens of µs, most of the
    threading planner's time): the same products and differences in the same order, so the
    same bits."""
    a0, a1, a2 = a.tolist() if isinstance(a, np.ndarray) else a
    b0, b1, b2 = b.tolist() if isinstance(b, np.ndarray) else b
    return np.array([a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0])


def rotvec_matrix(x: float, y: float, z: float) -> np.ndarray:
    """``Rotation.from_rotvec([x, y, z]).as_matrix()`` in plain floats: scipy's own formulas
    (half-angle quaternion, Taylor series below 1e-3 rad, then the quaternion's matrix) in its
    order of operations, so the same bits (``tests/geometry/test_skt.py`` holds them equal)."""
    angle = math.sqrt(x * x + y * y + z * z)
    if angle <= 1e-3:
        a2 = angle * angle
        scale = 0.5 - a2 / 48 + a2 * a2 / 3840
    else:
        scale = math.sin(angle / 2) / angle
    qx, qy, qz, w = scale * x, scale * y, scale * z, math.cos(angle / 2)
    x2, y2, z2, w2 = qx * qx, qy * qy, qz * qz, w * w
    xy, zw, xz, yw, yz, xw = qx * qy, qz * w, qx * qz, qy * w, qy * qz, qx * w
    return np.array([[x2 - y2 - z2 + w2, 2 * (xy - zw), 2 * (xz + yw)],
                     [2 * (xy + zw), -x2 + y2 - z2 + w2, 2 * (yz - xw)],
                     [2 * (xz - yw), 2 * (yz + xw), -x2 - y2 + z2 + w2]])


def minimal_rotation(a: np.ndarray, b: np.ndarray, fallback_axis: np.ndarray) -> np.ndarray:
    """The smallest rotation (3, 3) taking unit ``a`` onto unit ``b`` (Rodrigues); for
    opposite vectors, the half turn about ``fallback_axis`` (unit, ⊥ ``a``). Bit-equal to
    :func:`minimal_rotation_naive` (numpy's cross product and scipy's rotation vector),
    several times faster."""
    axis = cross3(a, b)
    s, c = np.linalg.norm(axis), float(np.clip(a @ b, -1.0, 1.0))
    if s < 1e-12:
        if c > 0:
            return np.eye(3)
        return 2.0 * np.outer(fallback_axis, fallback_axis) - np.eye(3)
    return rotvec_matrix(*(axis / s * math.atan2(s, c)).tolist())


def minimal_rotation_naive(a: np.ndarray, b: np.ndarray, fallback_axis: np.ndarray) -> np.ndarray:
    """Reference for :func:`minimal_rotation`: ``np.cross`` and scipy (for tests)."""
    axis = np.cross(a, b)
    s, c = np.linalg.norm(axis), float(np.clip(a @ b, -1.0, 1.0))
    if s < 1e-12:
        if c > 0:
            return np.eye(3)
        return 2.0 * np.outer(fallback_axis, fallback_axis) - np.eye(3)
    return Rotation.from_rotvec(axis / s * math.atan2(s, c)).as_matrix()


def skt_frames_naive(positions: np.ndarray) -> np.ndarray:
    """Reference for :func:`skt_frames`: the anchor frame turned waypoint by waypoint by the
    minimal rotation between consecutive motion directions (slow; for tests)."""
    positions = _as_positions(positions)
    t = motion_directions(positions)
    k, r_anchor = _anchor(positions)
    rots = [None] * len(t)
    rots[k] = r_anchor
    for i in list(range(k + 1, len(t))) + list(range(k - 1, -1, -1)):
        prev = i - 1 if i > k else i + 1
        rots[i] = minimal_rotation(t[prev], t[i], rots[prev][:, 1]) @ rots[prev]
    out = np.tile(np.eye(4), (len(positions), 1, 1))
    out[:, :3, :3] = np.stack(rots)
    out[:, :3, 3] = positions
    return out


def turning_length(positions: np.ndarray, turn_radius_m: float = TURN_RADIUS_M) -> np.ndarray:
    """Cumulative length ``(N,)`` along ``positions (N, 3)`` that counts travel plus turning:
    segment j weighs ``|Δp_j| + turn_radius_m · (θ_j + θ_{j+1}) / 2``, θ_j the turn of the
    motion direction at vertex j (half of each vertex's turn to each neighbouring segment)."""
    positions = _as_positions(positions)
    seg = np.diff(positions, axis=0)
    length = np.linalg.norm(seg, axis=1)
    t = motion_directions(positions)[:-1]  # direction of each segment
    turn = np.arccos(np.clip(np.sum(t[1:] * t[:-1], axis=1), -1.0, 1.0))  # at inner vertices
    at_vertex = np.concatenate([[0.0], turn, [0.0]])  # (N,)
    w = length + turn_radius_m * 0.5 * (at_vertex[:-1] + at_vertex[1:])
    return np.concatenate([[0.0], np.cumsum(w)])


def resample(positions: np.ndarray, n: int, turn_radius_m: float = TURN_RADIUS_M) -> np.ndarray:
    """``n`` points along the polyline ``positions (N, 3)``, equally spaced in travel plus
    turning (:func:`turning_length`; ``turn_radius_m = 0``: plain arc length); the first and
    last points are kept exactly."""
    positions = _as_positions(positions)
    if n < 2:
        raise ValueError(f"n: need at least 2 waypoints, got {n}")
    if arc_length(positions)[-1] <= 0:
        raise ValueError("positions: zero-length trajectory")
    s = turning_length(positions, turn_radius_m)
    keep = np.concatenate([[True], np.diff(s) > 0])  # zero-length steps add nothing
    s, pts = s[keep], positions[keep]
    targets = np.linspace(0.0, s[-1], n)
    out = np.stack([np.interp(targets, s, pts[:, k]) for k in range(3)], axis=1)
    out[0], out[-1] = positions[0], positions[-1]
    return out


def max_point_step(poses: np.ndarray, points: np.ndarray) -> float:
    """Largest displacement of any of ``points`` (object frame) between consecutive poses."""
    pts = np.stack([transform_points(t, points) for t in poses])
    return float(np.linalg.norm(np.diff(pts, axis=0), axis=2).max())


def interpolate(frames: np.ndarray, step_m: float, radius_m: float) -> np.ndarray:
    """Poses ``(M, 4, 4)`` through ``frames (T, 4, 4)`` (in execution order), adding
    in-between poses (linear position, slerp rotation) so that no point within ``radius_m``
    of the frame origin moves more than ``step_m`` between consecutive poses.

    All segments at once: scipy's per-element formulas on stacked inputs, so the result is
    :func:`interpolate_naive`'s (one ``Slerp`` per segment) bit for bit, several times faster."""
    frames = np.asarray(frames, float)
    rot, pos = frames[:, :3, :3], frames[:, :3, 3]
    rel = Rotation.from_matrix(np.matmul(rot[:-1].transpose(0, 2, 1), rot[1:])).magnitude()
    counts = [max(1, math.ceil((np.linalg.norm(d) + r * radius_m) / step_m))
              for d, r in zip(pos[1:] - pos[:-1], rel)]
    quats = Rotation.from_matrix(rot)
    start = quats[:-1]
    rotvecs = (start.inv() * quats[1:]).as_rotvec()
    seg = np.repeat(np.arange(len(counts)), counts)
    n = np.repeat(counts, counts)
    u = (np.arange(len(seg)) - np.repeat(np.cumsum(counts) - counts, counts) + 1) / n
    out = np.tile(np.eye(4), (len(seg) + 1, 1, 1))
    out[0] = frames[0]
    out[1:, :3, :3] = (start[seg] * Rotation.from_rotvec(rotvecs[seg] * u[:, None])).as_matrix()
    out[1:, :3, 3] = (1 - u)[:, None] * pos[seg] + u[:, None] * pos[seg + 1]
    return out


def interpolate_naive(frames: np.ndarray, step_m: float, radius_m: float) -> np.ndarray:
    """Reference for :func:`interpolate`: one ``Slerp`` per segment (for tests)."""
    out = [frames[0]]
    for a, b in zip(frames[:-1], frames[1:]):
        rel = Rotation.from_matrix(a[:3, :3].T @ b[:3, :3]).magnitude()
        n = max(1, math.ceil((np.linalg.norm(b[:3, 3] - a[:3, 3]) + rel * radius_m) / step_m))
        slerp = Slerp([0.0, 1.0], Rotation.from_matrix(np.stack([a[:3, :3], b[:3, :3]])))
        u = np.arange(1, n + 1) / n
        seg = np.tile(np.eye(4), (n, 1, 1))
        seg[:, :3, :3] = slerp(u).as_matrix()
        seg[:, :3, 3] = (1 - u)[:, None] * a[:3, 3] + u[:, None] * b[:3, 3]
        out.extend(seg)
    return np.stack(out)


def executed_path(positions: np.ndarray, step_m: float, radius_m: float) -> np.ndarray:
    """The SKT as it is executed and validated: keypoint frames ``(M, 4, 4)`` in execution
    order (ξ_{T-1} first, ξ_0 last) — :func:`skt_frames` of ``positions (T, 3)`` (ξ_0 first),
    interpolated so that no point within ``radius_m`` of the keypoint moves more than
    ``step_m`` per pose. ``sim_eval`` executes exactly this; ``rrt_skts`` re-checks exactly
    this."""
    return interpolate(skt_frames(np.asarray(positions, float))[::-1], step_m, radius_m)
