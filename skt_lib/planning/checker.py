"""The pose checker of the threading planner (:mod:`skt_lib.planning.threading`): every pose
the planner accepts is checked with the *probe* (the reference object, and when asked every
training object, at its own keypoint frame against the support and the wall), exactly as
execution will visit it — straight motion, slerped orientation, at most ``check_step_m`` of
probe-point motion between poses — and every check is counted against the budget
(``max_checks``: the planner's budget is counted in checks, not seconds)."""

from collections.abc import Callable

import numpy as np

from skt_lib.planning.frames import exec_frames_kept, rotation_quat, slerp, vec_norm
from skt_lib.planning.thread_settings import ThreadSettings


class Checker:
    """Counts pose checks against the budget; checks straight segments between two frames
    exactly as :func:`~skt_lib.geometry.skt.interpolate` executes them (linear
    position, slerp rotation, at most ``check_step_m`` of probe-point motion per pose)."""

    def __init__(self, collides: Callable[[np.ndarray, np.ndarray], bool], s: ThreadSettings):
        self.collides, self.s, self.n = collides, s, 0

    def frames(self, poses: np.ndarray) -> bool:
        """True when every pose ``(M, 4, 4)`` (keypoint frames, support frame) is clear."""
        for t in poses:
            self.n += 1
            if self.collides(t[:3, 3], rotation_quat(t[:3, :3])):
                return False
        return True

    def segment(self, pa, pb, ra, rb, qa=None, qb=None) -> bool:
        """Straight motion ``pa → pb`` with the orientation slerped ``ra → rb`` (as executed),
        ``pb`` included, ``pa`` not; ``qa``, ``qb``: their :func:`rotation_quat`, where known."""
        qa = rotation_quat(ra) if qa is None else qa
        qb = rotation_quat(rb) if qb is None else qb
        angle = 2.0 * np.arccos(min(1.0, abs(float(np.dot(qa, qb)))))
        n = max(1, int(np.ceil((vec_norm(pb - pa) + angle * self.s.probe_radius_m)
                               / self.s.check_step_m)))
        u = np.arange(1, n + 1) / n
        # all poses at once, as plain lists (the probe takes them a pose at a time)
        positions = (pa + np.outer(u, pb - pa)).tolist()
        quats = [qb.tolist()] * n if angle < 1e-9 else slerp(qa, qb, u).tolist()
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
                quats[k] = rotation_quat(frames[k][:3, :3])
            return quats[k]

        for k in todo:
            if not self.segment(points[k], points[k + 1], frames[k][:3, :3], frames[k + 1][:3, :3],
                                quat(k), quat(k + 1)):
                return None
        return frames
