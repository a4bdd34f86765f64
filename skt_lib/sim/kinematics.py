"""Serial-chain kinematics read from a URDF, in numpy, and an inverse kinematics that keeps
every joint inside its limits.

:class:`Chain` follows the joints from a URDF's root link to one tip link (fixed joints are
folded into the next transform), so forward kinematics and the geometric Jacobian are a few
small matrix products — no physics client, no state to reset.

:meth:`Chain.solve` is damped least squares on the 6-D pose error with the joint limits as
hard bounds (an active set: a joint whose step would leave its range is held at the bound
and the step is solved again for the others), plus a null-space pull toward a rest
configuration. Clipping a solution to the limits afterwards — what PyBullet's IK leaves to
its caller — moves the hand by millimetres exactly where a path runs along a limit; here the
limit is part of the solve.

The solve runs compiled (:mod:`skt_lib.sim.ik_kernel`, numba) unless the chain is built with
``compiled=False``: then the numpy code below, the reference it is tested against.
"""

import xml.etree.ElementTree as ET
from dataclasses import dataclass

import numpy as np

from skt_lib.sim import ik_kernel


def _rpy_matrix(rpy) -> np.ndarray:
    r, p, y = rpy
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def _origin(joint: ET.Element) -> np.ndarray:
    t = np.eye(4)
    o = joint.find("origin")
    if o is not None:
        t[:3, :3] = _rpy_matrix([float(v) for v in o.get("rpy", "0 0 0").split()])
        t[:3, 3] = [float(v) for v in o.get("xyz", "0 0 0").split()]
    return t


def rotation_error(target: np.ndarray, current: np.ndarray) -> np.ndarray:
    """Rotation vector (3,) of ``target @ current.T`` (world frame): the rotation that takes
    ``current`` (3×3) to ``target`` (3×3)."""
    r = target @ current.T
    cos = np.clip((np.trace(r) - 1.0) / 2.0, -1.0, 1.0)
    axis = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    sin2 = np.linalg.norm(axis)  # = 2 sin(angle)
    angle = np.arctan2(sin2 / 2.0, cos)
    if sin2 > 1e-9:
        return axis * (angle / sin2)
    if cos > 0.0:
        return axis / 2.0
    # angle ≈ π: the axis is the column of r + I with the largest norm
    m = r + np.eye(3)
    k = int(np.argmax(np.linalg.norm(m, axis=0)))
    return np.pi * m[:, k] / np.linalg.norm(m[:, k])


@dataclass(frozen=True)
class IKSettings:
    """``tol_m``/``tol_rad``: accepted pose error; ``damping``: DLS damping (m-equivalent);
    ``rot_weight_m``: metres one radian of rotation error counts as; ``max_step_rad``:
    largest joint change per iteration; ``rest_gain``: null-space pull toward the rest
    configuration per iteration (fraction of the distance; with a pull, at least one
    iteration is taken even from a pose already within tolerance)."""

    tol_m: float = 1e-4
    tol_rad: float = 1e-3
    max_iterations: int = 60
    damping: float = 1e-3
    rot_weight_m: float = 0.2
    max_step_rad: float = 0.3
    rest_gain: float = 0.05


class Chain:
    """The revolute/prismatic chain of ``urdf`` from its root to ``tip`` (a link name),
    with its base at ``base`` (4×4, world); ``compiled``: solve with the numba kernel."""

    def __init__(self, urdf: str, tip: str, base: np.ndarray | None = None,
                 compiled: bool = True):
        root = ET.parse(urdf).getroot()
        by_child = {j.find("child").get("link"): j for j in root.findall("joint")}
        chain, link = [], tip
        while link in by_child:
            chain.append(by_child[link])
            link = by_child[link].find("parent").get("link")
        if not chain:
            raise ValueError(f"{urdf}: no joint leads to link {tip!r}")
        chain.reverse()
        self.base = np.eye(4) if base is None else np.asarray(base, float)
        self.names: list[str] = []
        self.axes: list[np.ndarray] = []
        self.prismatic: list[bool] = []
        lower, upper = [], []
        # _pre[i]: fixed transform before movable joint i; _tail: after the last one
        self._pre: list[np.ndarray] = []
        pending = np.eye(4)
        for j in chain:
            pending = pending @ _origin(j)
            kind = j.get("type")
            if kind == "fixed":
                continue
            if kind not in ("revolute", "prismatic"):
                raise ValueError(f"{urdf}: joint {j.get('name')!r} of type {kind!r} "
                                 "is not supported")
            lim = j.find("limit")
            self.names.append(j.get("name"))
            self.axes.append(np.array([float(v) for v in j.find("axis").get("xyz").split()]))
            self.prismatic.append(kind == "prismatic")
            lower.append(float(lim.get("lower")))
            upper.append(float(lim.get("upper")))
            self._pre.append(pending)
            pending = np.eye(4)
        self._tail = pending
        self._prismatic = np.array(self.prismatic)
        self._skew = []
        for a in self.axes:
            k = np.array([[0.0, -a[2], a[1]], [a[2], 0.0, -a[0]], [-a[1], a[0], 0.0]])
            self._skew.append((k, k @ k))
        self.lower, self.upper = np.array(lower), np.array(upper)
        self.n = len(self.names)
        self.compiled = compiled
        self._packed = (np.ascontiguousarray(self.base), np.stack(self._pre), self._tail,
                        np.stack(self.axes), np.stack([k for k, _ in self._skew]),
                        np.stack([kk for _, kk in self._skew]), self._prismatic,
                        self.lower, self.upper)

    def _joint(self, i: int, v: float) -> np.ndarray:
        """Motion (4×4) of movable joint ``i`` at value ``v`` (Rodrigues for revolute)."""
        t = np.eye(4)
        if self.prismatic[i]:
            t[:3, 3] = self.axes[i] * v
        else:
            k, kk = self._skew[i]
            t[:3, :3] += np.sin(v) * k + (1.0 - np.cos(v)) * kk
        return t

    def fk(self, q) -> np.ndarray:
        """World pose (4×4) of the tip at joints ``q`` (n,)."""
        t = self.base
        for i in range(self.n):
            t = t @ self._pre[i] @ self._joint(i, float(q[i]))
        return t @ self._tail

    def fk_jacobian(self, q) -> tuple[np.ndarray, np.ndarray]:
        """Tip pose (4×4, world) and geometric Jacobian ``(6, n)`` (linear over angular,
        world frame, at the tip origin)."""
        t = self.base
        axes, origins = np.empty((self.n, 3)), np.empty((self.n, 3))
        for i in range(self.n):
            t = t @ self._pre[i]
            axes[i] = t[:3, :3] @ self.axes[i]
            origins[i] = t[:3, 3]
            t = t @ self._joint(i, float(q[i]))
        t = t @ self._tail
        jac = np.empty((6, self.n))
        rev = ~self._prismatic
        jac[:3] = np.where(rev[:, None], np.cross(axes, t[:3, 3] - origins), axes).T
        jac[3:] = np.where(rev[:, None], axes, 0.0).T
        return t, jac

    def pose_error(self, q, target: np.ndarray) -> tuple[float, float]:
        """(position error m, rotation error rad) of the tip at ``q`` against ``target``."""
        t = self.fk(q)
        return (float(np.linalg.norm(target[:3, 3] - t[:3, 3])),
                float(np.linalg.norm(rotation_error(target[:3, :3], t[:3, :3]))))

    def solve(self, target: np.ndarray, q_init, q_rest=None,
              settings: IKSettings = IKSettings()) -> tuple[np.ndarray, float, float]:
        """Joints (n,) inside the limits that put the tip at ``target`` (4×4, world),
        iterated from ``q_init`` and pulled toward ``q_rest`` (default ``q_init``) in the
        null space; returns ``(q, position error m, rotation error rad)`` of the best
        iterate (the errors tell whether it converged)."""
        s = settings
        lo, hi = self.lower, self.upper
        q = np.clip(np.asarray(q_init, float), lo, hi)
        rest = q.copy() if q_rest is None else np.asarray(q_rest, float)
        if self.compiled:
            q, d, a = ik_kernel.solve(*self._packed, np.ascontiguousarray(target, float), q, rest,
                                      s.tol_m, s.tol_rad, s.max_iterations, s.damping,
                                      s.rot_weight_m, s.max_step_rad, s.rest_gain)
            return q, float(d), float(a)
        w = np.array([1.0, 1.0, 1.0, s.rot_weight_m, s.rot_weight_m, s.rot_weight_m])
        best = (q.copy(), np.inf, np.inf)
        for it in range(s.max_iterations):
            t, jac = self.fk_jacobian(q)
            e_rot = rotation_error(target[:3, :3], t[:3, :3])
            d, a = float(np.linalg.norm(target[:3, 3] - t[:3, 3])), float(np.linalg.norm(e_rot))
            if d / s.tol_m + a / s.tol_rad < best[1] / s.tol_m + best[2] / s.tol_rad:
                best = (q.copy(), d, a)
            if d <= s.tol_m and a <= s.tol_rad and (it > 0 or s.rest_gain == 0.0):
                break
            err = w * np.concatenate([target[:3, 3] - t[:3, 3], e_rot])
            dq = self._bounded_step(w[:, None] * jac, err, q, rest, s)
            q = np.clip(q + dq, lo, hi)
        return best

    def track(self, targets: np.ndarray, q_start, q_rest, settings: IKSettings, tol_m: float,
              tol_rad: float, max_jump: float) -> tuple[np.ndarray, tuple | None]:
        """Solve each of ``targets (K, 4, 4)`` in order, from the solution before it
        (``q_start`` before the first), pulled toward ``q_rest``; stop at the first solution
        off ``target`` by more than ``tol_m``/``tol_rad`` or more than ``max_jump`` (any
        joint) from the one before. Returns ``(path (K + 1, n), None)`` with ``q_start``
        first, or ``(path so far, (check, k, d, a, jump))`` — ``check`` "tracking_tolerance"
        or "joint_jump" at target ``k`` — exactly as one :meth:`solve` per target would
        (compiled: one kernel call for the whole path, :func:`ik_kernel.track`)."""
        s = settings
        if self.compiled:
            path, status, k, d, a, jump = ik_kernel.track(
                *self._packed, np.ascontiguousarray(targets, float), np.asarray(q_start, float),
                np.asarray(q_rest, float), s.tol_m, s.tol_rad, s.max_iterations, s.damping,
                s.rot_weight_m, s.max_step_rad, s.rest_gain, tol_m, tol_rad, max_jump)
            if status == 0:
                return path, None
            check = "tracking_tolerance" if status == 1 else "joint_jump"
            return path[:k + 1], (check, int(k), float(d), float(a), float(jump))
        return self.track_naive(targets, q_start, q_rest, settings, tol_m, tol_rad, max_jump)

    def track_naive(self, targets: np.ndarray, q_start, q_rest, settings: IKSettings,
                    tol_m: float, tol_rad: float,
                    max_jump: float) -> tuple[np.ndarray, tuple | None]:
        """:meth:`track` as one :meth:`solve` call per target: the numpy chain's tracker and
        the reference the compiled one is tested bit-equal against."""
        path = [np.asarray(q_start, float)]
        for k, target in enumerate(targets):
            q, d, a = self.solve(target, path[-1], q_rest, settings)
            jump = float(np.abs(q - path[-1]).max())
            if d > tol_m or a > tol_rad:
                return np.stack(path), ("tracking_tolerance", k, d, a, jump)
            if jump > max_jump:
                return np.stack(path), ("joint_jump", k, d, a, jump)
            path.append(q)
        return np.stack(path), None

    def _bounded_step(self, jac, err, q, rest, s: IKSettings) -> np.ndarray:
        """One DLS step with the null-space rest pull, the joints that would leave their
        range held at the bound (active set, at most n rounds), scaled to ``max_step_rad``."""
        free = np.ones(self.n, bool)
        dq = np.zeros(self.n)
        for _ in range(self.n):
            resid = err - jac[:, ~free] @ dq[~free]
            jf = jac[:, free]
            jj = jf @ jf.T + (s.damping ** 2) * np.eye(6)
            pinv = jf.T @ np.linalg.solve(jj, np.eye(6))
            pull = s.rest_gain * (rest - q)[free]
            dq[free] = pinv @ resid + (np.eye(int(free.sum())) - pinv @ jf) @ pull
            out = free & ((q + dq < self.lower) | (q + dq > self.upper))
            if not out.any():
                break
            dq[out] = np.clip(dq[out], self.lower[out] - q[out], self.upper[out] - q[out])
            free &= ~out
            if not free.any():
                break
        big = np.abs(dq).max()
        return dq * (s.max_step_rad / big) if big > s.max_step_rad else dq
