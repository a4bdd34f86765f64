"""Where an SKT of the threading planner (:mod:`skt_lib.planning.threading`) ends: the
release ξ_0 and the straight lead-in into it, the root of every tree.

ξ_0 is the hanging keypoint or, where the probe does not fit there (a ring tilted along an
angled peg meets the wall plate at the hang), a point at most ``max_release_offset_m``
(≤ 4 mm) from it, lifted above it and/or moved back along the arrival
(:func:`release_offsets`); the last ``lead_in_m`` is a straight line along the arrival
direction — the hanging keypoint's x axis or, where that is blocked, the nearest clear
direction turned from it (:func:`arrival_directions`) — whose rule frame anchors the SKT
frames: the hanging orientation the object ends at. :func:`releases` yields the candidates
in the order the planners try them."""

import numpy as np

from skt_lib.geometry.se3 import skt_rotation
from skt_lib.planning.checker import Checker
from skt_lib.planning.frames import frame, unit
from skt_lib.planning.thread_settings import ThreadingFailed, ThreadSettings



#: Release offsets tried first: lifts above the hang in steps of this (m); then the rest of
#: a grid of :data:`RELEASE_STEP_M` (lift and back along the arrival).
LIFT_STEP_M = 0.002
RELEASE_STEP_M = 0.001



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
        out.append(unit(d))
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


def releases(hang: np.ndarray, a0: np.ndarray, check: Checker, s: ThreadSettings):
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
                if check.frames(frame(lead[-1], r0)[None]) and check.segment(lead[-1], p0, r0, r0):
                    found = True
                    yield lead, d, r0
    if not found:
        raise ThreadingFailed("no clear straight lead-in at the hang or near it",
                              "lead_in_blocked")
