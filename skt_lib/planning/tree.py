"""The search tree of the threading planner (:mod:`skt_lib.planning.threading`) and the
sampler that grows it.

The tree (:class:`Tree`) grows *backward* from the release ξ_0 at the hang (its straight
lead-in: :mod:`skt_lib.planning.release`), with edges of ``step_m``; each node carries the
frame its parent's is transported to along the edge, so frames are defined while the tree
grows (vertical motion included), and an edge may turn the motion by at most
``max_turn_deg`` from the next one. Adding a child re-checks its parent's edge with the
orientation that child gives it. A node in the start region is a *leaf*: it ends a path.

Samples (:class:`Sampler`) are drawn in the start region (``goal_bias``), near the support's
surface (``surface_bias``), near the hanging arm's threading route (``route_bias``,
:mod:`skt_lib.planning.route`), or uniformly in the bounds; a ``plane_bias`` share of them,
of every kind but the route's, is moved onto the *threading plane*
(:func:`threading_plane`), where a ring goes over a tip and down it without turning sideways."""

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from skt_lib.planning.checker import Checker
from skt_lib.planning.frames import limit_direction, rotation_quat, transport
from skt_lib.planning.thread_settings import ThreadingFailed, ThreadSettings


#: A tree that has added fewer than STUCK_NODES nodes after STUCK_CHECKS checks is stuck at
#: its release: the next release candidate is tried.
STUCK_CHECKS, STUCK_NODES = 1500, 3


@dataclass(frozen=True)
class Sampler:
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


class Tree:
    """The backward tree of one release: grown from the lead-in's far end, nodes at most
    ``step_m`` apart, each with the frame transported to it (module notes).

    Node v (not the root) stores ``dirs[v]``, the execution direction from v to its parent,
    and ``rots[v]``, the SKT frame at its parent when the path runs through v (x = ``dirs[v]``):
    the parent's own ``rots`` transported onto ``dirs[v]``. Positions live in a growing array
    (the nearest-node query is one vectorised distance); a node in the start region is a
    *leaf*: it ends a path and is never extended, so every later leaf is a path of its own."""

    def __init__(self, lead: np.ndarray, a0: np.ndarray, r0: np.ndarray, lower, upper,
                 check: Checker, s: ThreadSettings):
        self.lower, self.upper, self.check, self.s = lower, upper, check, s
        self.turn = np.radians(s.max_turn_deg)
        self.n_lead = len(lead)
        self._pos = np.empty((max(1024, 2 * len(lead)), 3))
        self._pos[:len(lead)] = lead
        self.n = len(lead)
        self.dirs = [a0] * len(lead)
        self.rots = [r0] * len(lead)
        self.quats = [rotation_quat(r0)] * len(lead)  # :func:`rotation_quat` of each of ``rots``
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
            qd = rotation_quat(rd)
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
