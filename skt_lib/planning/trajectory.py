"""Keypoint trajectories: conversion from object poses, SKT frames, resampling.

An SKT is ``T`` waypoints ξ_0..ξ_{T-1} in the support frame, ξ_0 at the hanging pose;
execution runs ξ_{T-1} → ξ_0. Positions are ``(T, 3)`` float64 metres.
"""

import math

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from skt_lib.geometry.se3 import GRAVITY_DIR, transform_points


def keypoint_positions(poses: np.ndarray, keypoint: np.ndarray) -> np.ndarray:
    """Keypoint positions ``(N, 3)`` for object poses ``(N, 4, 4)`` and an object-frame
    keypoint ``(3,)``."""
    poses = np.asarray(poses)
    return np.einsum("nij,j->ni", poses[:, :3, :3], keypoint) + poses[:, :3, 3]


def arc_length(positions: np.ndarray) -> np.ndarray:
    """Cumulative arc length ``(N,)`` starting at 0."""
    return np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(positions, axis=0), axis=1))])


def resample(positions: np.ndarray, n: int) -> np.ndarray:
    """``n`` points at equal arc-length spacing along the polyline ``positions (N, 3)``;
    the first and last points are kept exactly."""
    positions = np.asarray(positions, dtype=np.float64)
    if positions.ndim != 2 or positions.shape[1] != 3 or len(positions) < 2:
        raise ValueError(f"positions: expected (N>=2, 3), got {positions.shape}")
    if n < 2:
        raise ValueError(f"n: need at least 2 waypoints, got {n}")
    s = arc_length(positions)
    if s[-1] <= 0:
        raise ValueError("positions: zero-length trajectory")
    targets = np.linspace(0.0, s[-1], n)
    out = np.stack([np.interp(targets, s, positions[:, k]) for k in range(3)], axis=1)
    out[0], out[-1] = positions[0], positions[-1]
    return out


def skt_frames(positions: np.ndarray) -> np.ndarray:
    """SE(3) waypoints ``(T, 4, 4)`` for SKT positions ``(T, 3)`` ordered ξ_0 (hang) first.

    Each waypoint's x axis is the unit direction of motion toward the hang (from ξ_{i+1} to
    ξ_i; ξ_{T-1} reuses the next segment), y = x × g, z = x × y (:func:`skt_rotation`,
    vectorised). Where the rule is undefined (vertical or zero motion) a waypoint takes the
    rotation of the nearest waypoint where it is defined (the lower index on a tie)."""
    positions = np.asarray(positions, dtype=np.float64)
    motion = positions[:-1] - positions[1:]  # motion arriving at waypoint i (execution order)
    motion = np.vstack([motion, motion[-1:]])
    with np.errstate(invalid="ignore", divide="ignore"):
        norm = np.linalg.norm(motion, axis=1)
        x = motion / norm[:, None]
        y = np.cross(x, GRAVITY_DIR)
        y_norm = np.linalg.norm(y, axis=1)
        known = np.isfinite(norm) & (norm >= 1e-12) & np.isfinite(y_norm) & (y_norm >= 1e-6)
        y = y / y_norm[:, None]
    if not known.any():
        raise ValueError("positions: every segment is vertical; SKT rotations are undefined")
    rots = np.stack([x, y, np.cross(x, y)], axis=2)
    k = np.flatnonzero(known)
    nearest = k[np.abs(k[None, :] - np.arange(len(positions))[:, None]).argmin(1)]
    out = np.tile(np.eye(4), (len(positions), 1, 1))
    out[:, :3, :3] = rots[nearest]
    out[:, :3, 3] = positions
    return out


def max_point_step(poses: np.ndarray, points: np.ndarray) -> float:
    """Largest displacement of any of ``points`` (object frame) between consecutive poses."""
    pts = np.stack([transform_points(t, points) for t in poses])
    return float(np.linalg.norm(np.diff(pts, axis=0), axis=2).max())


def interpolate(frames: np.ndarray, step_m: float, radius_m: float) -> np.ndarray:
    """Poses ``(M, 4, 4)`` through ``frames (T, 4, 4)`` (in execution order), adding
    in-between poses (linear position, slerp rotation) so that no point within ``radius_m``
    of the frame origin moves more than ``step_m`` between consecutive poses."""
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
