"""The set-up IK's inner loop compiled with numba: the same damped least squares with
joint-limit bounds and null-space rest pull as :meth:`skt_lib.sim.kinematics.Chain.solve`
(the numpy version, kept as the readable reference and as the reference executor's IK),
step for step, without numpy's per-call overhead on 6×7 matrices.

Set-up solves a few hundred poses per grasp candidate; in numpy a solve iteration costs
~0.3 ms of call overhead, here a few microseconds. ``tests/sim/test_kinematics.py`` checks
that both give the same joints. Compiled once per machine (``cache=True``: numba's cache
beside this file, or ``NUMBA_CACHE_DIR``).
"""

import numpy as np
from numba import njit


@njit(cache=True)
def _mul44(a, b):
    out = np.empty((4, 4))
    for i in range(4):
        for j in range(4):
            out[i, j] = (a[i, 0] * b[0, j] + a[i, 1] * b[1, j] + a[i, 2] * b[2, j]
                         + a[i, 3] * b[3, j])
    return out


@njit(cache=True)
def fk_jacobian(base, pre, tail, axes, skew, skew2, prismatic, q):
    """Tip pose (4×4) and geometric Jacobian (6, n) at ``q``: the chain as
    :class:`~skt_lib.sim.kinematics.Chain` stores it (``pre`` (n, 4, 4), ``skew``/``skew2``
    (n, 3, 3): the axis' cross-product matrix and its square)."""
    n = q.shape[0]
    t = base.copy()
    axes_w = np.empty((n, 3))
    origins = np.empty((n, 3))
    m = np.empty((4, 4))
    for i in range(n):
        t = _mul44(t, pre[i])
        for r in range(3):
            axes_w[i, r] = t[r, 0] * axes[i, 0] + t[r, 1] * axes[i, 1] + t[r, 2] * axes[i, 2]
            origins[i, r] = t[r, 3]
        m[:] = 0.0
        for r in range(4):
            m[r, r] = 1.0
        if prismatic[i]:
            for r in range(3):
                m[r, 3] = axes[i, r] * q[i]
        else:
            s, c = np.sin(q[i]), 1.0 - np.cos(q[i])
            for r in range(3):
                for k in range(3):
                    m[r, k] += s * skew[i, r, k] + c * skew2[i, r, k]
        t = _mul44(t, m)
    t = _mul44(t, tail)
    jac = np.zeros((6, n))
    for i in range(n):
        a = axes_w[i]
        if prismatic[i]:
            jac[:3, i] = a
        else:
            r0, r1, r2 = t[0, 3] - origins[i, 0], t[1, 3] - origins[i, 1], t[2, 3] - origins[i, 2]
            jac[0, i] = a[1] * r2 - a[2] * r1
            jac[1, i] = a[2] * r0 - a[0] * r2
            jac[2, i] = a[0] * r1 - a[1] * r0
            jac[3:, i] = a
    return t, jac


@njit(cache=True)
def rotation_error(target, current):
    """Rotation vector (3,) taking ``current`` (3×3) to ``target`` (3×3), world frame."""
    r = np.empty((3, 3))
    for i in range(3):
        for j in range(3):
            r[i, j] = (target[i, 0] * current[j, 0] + target[i, 1] * current[j, 1]
                       + target[i, 2] * current[j, 2])
    cos = min(max((r[0, 0] + r[1, 1] + r[2, 2] - 1.0) / 2.0, -1.0), 1.0)
    axis = np.array([r[2, 1] - r[1, 2], r[0, 2] - r[2, 0], r[1, 0] - r[0, 1]])
    sin2 = np.sqrt(axis[0] ** 2 + axis[1] ** 2 + axis[2] ** 2)
    angle = np.arctan2(sin2 / 2.0, cos)
    if sin2 > 1e-9:
        return axis * (angle / sin2)
    if cos > 0.0:
        return axis / 2.0
    m = r + np.eye(3)
    norms = np.sqrt((m * m).sum(axis=0))
    k = np.argmax(norms)
    return np.pi * m[:, k] / norms[k]


@njit(cache=True)
def _spd_inverse(a):
    """Inverse of a symmetric positive-definite matrix (Cholesky)."""
    n = a.shape[0]
    low = np.zeros((n, n))
    for j in range(n):
        d = a[j, j]
        for k in range(j):
            d -= low[j, k] ** 2
        low[j, j] = np.sqrt(d)
        for i in range(j + 1, n):
            v = a[i, j]
            for k in range(j):
                v -= low[i, k] * low[j, k]
            low[i, j] = v / low[j, j]
    inv = np.zeros((n, n))
    for c in range(n):  # solve L y = e_c, then Lᵀ x = y
        y = np.zeros(n)
        for i in range(n):
            v = 1.0 if i == c else 0.0
            for k in range(i):
                v -= low[i, k] * y[k]
            y[i] = v / low[i, i]
        for i in range(n - 1, -1, -1):
            v = y[i]
            for k in range(i + 1, n):
                v -= low[k, i] * inv[k, c]
            inv[i, c] = v / low[i, i]
    return inv


@njit(cache=True)
def bounded_step(jac, err, q, rest, lower, upper, damping, rest_gain, max_step):
    """One DLS step with the null-space rest pull; joints that would leave their range are
    held at the bound and the step solved again for the others; scaled to ``max_step``."""
    n = q.shape[0]
    free = np.ones(n, np.bool_)
    dq = np.zeros(n)
    for _ in range(n):
        idx = np.nonzero(free)[0]
        m = idx.shape[0]
        resid = err.copy()
        for j in range(n):
            if not free[j]:
                for r in range(6):
                    resid[r] -= jac[r, j] * dq[j]
        jj = np.empty((6, 6))
        for r in range(6):
            for c in range(6):
                v = 0.0
                for k in idx:
                    v += jac[r, k] * jac[c, k]
                jj[r, c] = v + (damping ** 2 if r == c else 0.0)
        inv = _spd_inverse(jj)
        pinv = np.zeros((m, 6))  # jfᵀ (jf jfᵀ + λ² I)⁻¹
        for a in range(m):
            for c in range(6):
                v = 0.0
                for r in range(6):
                    v += jac[r, idx[a]] * inv[r, c]
                pinv[a, c] = v
        pull = np.empty(m)
        for a in range(m):
            pull[a] = rest_gain * (rest[idx[a]] - q[idx[a]])
        jpull = np.zeros(6)  # jf @ pull
        for r in range(6):
            for a in range(m):
                jpull[r] += jac[r, idx[a]] * pull[a]
        any_out = False
        for a in range(m):
            v = pull[a]
            for r in range(6):
                v += pinv[a, r] * (resid[r] - jpull[r])
            j = idx[a]
            dq[j] = v
            if q[j] + v < lower[j] or q[j] + v > upper[j]:
                any_out = True
        if not any_out:
            break
        for j in idx:
            if q[j] + dq[j] < lower[j] or q[j] + dq[j] > upper[j]:
                dq[j] = min(max(dq[j], lower[j] - q[j]), upper[j] - q[j])
                free[j] = False
        if not free.any():
            break
    big = np.abs(dq).max()
    return dq * (max_step / big) if big > max_step else dq


@njit(cache=True)
def solve(base, pre, tail, axes, skew, skew2, prismatic, lower, upper, target, q_init, rest,
          tol_m, tol_rad, max_iterations, damping, rot_weight_m, max_step, rest_gain):
    """:meth:`~skt_lib.sim.kinematics.Chain.solve`: ``(q, position error, rotation error)``
    of the best iterate."""
    q = np.minimum(np.maximum(q_init, lower), upper)
    w = np.array([1.0, 1.0, 1.0, rot_weight_m, rot_weight_m, rot_weight_m])
    best_q, best_d, best_a = q.copy(), np.inf, np.inf
    err = np.empty(6)
    wjac = np.empty((6, q.shape[0]))
    for it in range(max_iterations):
        t, jac = fk_jacobian(base, pre, tail, axes, skew, skew2, prismatic, q)
        e_rot = rotation_error(target[:3, :3], t[:3, :3])
        dp = target[:3, 3] - t[:3, 3]
        d, a = np.sqrt(dp @ dp), np.sqrt(e_rot @ e_rot)
        if d / tol_m + a / tol_rad < best_d / tol_m + best_a / tol_rad:
            best_q, best_d, best_a = q.copy(), d, a
        if d <= tol_m and a <= tol_rad and (it > 0 or rest_gain == 0.0):
            break
        err[:3] = dp
        err[3:] = e_rot
        err *= w
        for r in range(6):
            wjac[r] = w[r] * jac[r]
        dq = bounded_step(wjac, err, q, rest, lower, upper, damping, rest_gain, max_step)
        q = np.minimum(np.maximum(q + dq, lower), upper)
    return best_q, best_d, best_a
