"""Frames and quaternions of the threading planner (:mod:`skt_lib.planning.threading`).

An SKT is executed with its rotation-minimizing frames (:func:`~skt_lib.geometry.skt.skt_frames`:
x = direction of motion, the roll carried along the path from the hanging orientation); the
planner grows its tree *backward* from the hang, so here are those frames in execution order
(:func:`exec_frames`, and :func:`exec_frames_kept` when only the start side of a path
changed), one transport step (:func:`transport`), the turn limit (:func:`limit_direction`),
and the small vector and quaternion helpers the checker and the tree call hundreds of
thousands of times — each bit for bit the numpy / scipy computation it replaces."""

import math

import numpy as np

from skt_lib.geometry.skt import cross3, minimal_rotation, skt_frames


def vec_norm(v: np.ndarray) -> float:
    """``np.linalg.norm`` of a float vector, bit for bit (it is ``sqrt(v.dot(v))``), without its
    per-call overhead: the planner takes hundreds of thousands."""
    return math.sqrt(float(v.dot(v)))


def unit(v: np.ndarray) -> np.ndarray:
    return v / vec_norm(v)


def angle(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.arccos(np.clip(np.dot(a, b), -1.0, 1.0)))


def limit_direction(d: np.ndarray, prev: np.ndarray, max_turn: float) -> np.ndarray:
    """Unit direction closest to ``d`` within ``max_turn`` rad of ``prev`` (unit)."""
    d = unit(np.asarray(d, float))
    if angle(d, prev) > max_turn:
        axis = cross3(prev, d)
        if np.linalg.norm(axis) < 1e-9:  # opposite: turn about a horizontal axis
            axis = cross3(prev, (0.0, 0.0, 1.0))
            if np.linalg.norm(axis) < 1e-9:
                axis = np.array([0.0, 1.0, 0.0])
        axis = unit(axis)
        d = prev * np.cos(max_turn) + cross3(axis, prev) * np.sin(max_turn)
    return unit(d)


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
        y[i] = r / vec_norm(r)
    out = np.empty((n, 4, 4))
    out[m + 1:] = old_frames[-(n - m - 1):]
    new = np.tile(np.eye(4), (m + 1, 1, 1))
    new[:, :3, :3] = np.stack([t[1:], y[1:], np.cross(t[1:], y[1:])], axis=2)[::-1]
    new[:, :3, 3] = points[: m + 1]
    out[: m + 1] = new
    return out


def rotation_quat(r: np.ndarray) -> np.ndarray:
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
    return q / vec_norm(q)


def slerp(q0: np.ndarray, q1: np.ndarray, u: np.ndarray) -> np.ndarray:
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


def frame(p: np.ndarray, r: np.ndarray) -> np.ndarray:
    t = np.eye(4)
    t[:3, :3], t[:3, 3] = r, p
    return t
