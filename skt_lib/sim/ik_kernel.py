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
def _mul44_into(a, b, out):
    """``out = a @ b`` (4×4; ``out`` must not be ``a`` or ``b``)."""
    for i in range(4):
        for j in range(4):
            out[i, j] = (a[i, 0] * b[0, j] + a[i, 1] * b[1, j] + a[i, 2] * b[2, j]
                         + a[i, 3] * b[3, j])


@njit(cache=True)
def _mul44(a, b):
    out = np.empty((4, 4))
    _mul44_into(a, b, out)
    return out


@njit(cache=True)
def fk_jacobian(base, pre, tail, axes, skew, skew2, prismatic, q):
    """Tip pose (4×4) and geometric Jacobian (6, n) at ``q``: the chain as
    :class:`~skt_lib.sim.kinematics.Chain` stores it (``pre`` (n, 4, 4), ``skew``/``skew2``
    (n, 3, 3): the axis' cross-product matrix and its square)."""
    n = q.shape[0]
    t = base.copy()
    u = np.empty((4, 4))  # t and u take turns as the product (no array per multiplication)
    axes_w = np.empty((n, 3))
    origins = np.empty((n, 3))
    m = np.empty((4, 4))
    for i in range(n):
        _mul44_into(t, pre[i], u)
        t, u = u, t
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
        _mul44_into(t, m, u)
        t, u = u, t
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
def _spd_inverse(a, low, inv, y):
    """``inv`` = inverse of the symmetric positive-definite ``a`` (Cholesky); ``low``
    (n, n) and ``y`` (n,) are work arrays (every entry read is written first)."""
    n = a.shape[0]
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
    for c in range(n):  # solve L y = e_c, then Lᵀ x = y
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


@njit(cache=True)
def workspace(n):
    """The work arrays of :func:`bounded_step` for ``n`` joints, made once per solve (not
    once per iteration: allocation was a fifth of the solve's time)."""
    return (np.empty(n, np.bool_), np.empty(n), np.empty(n, np.int64), np.empty(6),
            np.empty((6, 6)), np.empty((6, 6)), np.empty((6, 6)), np.empty(6),
            np.empty((n, 6)), np.empty(n), np.empty(6))


@njit(cache=True)
def bounded_step(jac, err, q, rest, lower, upper, damping, rest_gain, max_step, ws):
    """One DLS step with the null-space rest pull; joints that would leave their range are
    held at the bound and the step solved again for the others; scaled to ``max_step``.
    ``ws``: :func:`workspace`; the step is returned in its ``dq`` (valid until the next call)."""
    free, dq, idx, resid, jj, low, inv, y, pinv, pull, jpull = ws
    n = q.shape[0]
    free[:] = True
    dq[:] = 0.0
    for _ in range(n):
        m = 0
        for j in range(n):
            if free[j]:
                idx[m] = j
                m += 1
        resid[:] = err
        for j in range(n):
            if not free[j]:
                for r in range(6):
                    resid[r] -= jac[r, j] * dq[j]
        for r in range(6):
            for c in range(6):
                v = 0.0
                for a in range(m):
                    k = idx[a]
                    v += jac[r, k] * jac[c, k]
                jj[r, c] = v + (damping ** 2 if r == c else 0.0)
        _spd_inverse(jj, low, inv, y)
        for a in range(m):  # pinv = jfᵀ (jf jfᵀ + λ² I)⁻¹
            for c in range(6):
                v = 0.0
                for r in range(6):
                    v += jac[r, idx[a]] * inv[r, c]
                pinv[a, c] = v
        for a in range(m):
            pull[a] = rest_gain * (rest[idx[a]] - q[idx[a]])
        jpull[:] = 0.0  # jf @ pull
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
        for a in range(m):
            j = idx[a]
            if q[j] + dq[j] < lower[j] or q[j] + dq[j] > upper[j]:
                dq[j] = min(max(dq[j], lower[j] - q[j]), upper[j] - q[j])
                free[j] = False
        if not free.any():
            break
    big = 0.0  # np.abs(dq).max()
    for j in range(n):
        big = max(big, abs(dq[j]))
    if big > max_step:
        scale = max_step / big
        for j in range(n):
            dq[j] = dq[j] * scale
    return dq


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
    ws = workspace(q.shape[0])
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
        dq = bounded_step(wjac, err, q, rest, lower, upper, damping, rest_gain, max_step, ws)
        for j in range(q.shape[0]):  # np.minimum(np.maximum(q + dq, lower), upper), in place
            q[j] = min(max(q[j] + dq[j], lower[j]), upper[j])
    return best_q, best_d, best_a


@njit(cache=True)
def track(base, pre, tail, axes, skew, skew2, prismatic, lower, upper, targets, q_start, rest,
          ik_tol_m, ik_tol_rad, max_iterations, damping, rot_weight_m, max_step, rest_gain,
          tol_m, tol_rad, max_jump):
    """:meth:`~skt_lib.sim.kinematics.Chain.track`: each of ``targets (K, 4, 4)`` solved in
    order from the previous solution (``q_start`` before the first); ``(path (K + 1, n),
    status, k, d, a, jump)`` — status 0: every target within ``tol_m``/``tol_rad`` and
    ``max_jump``; 1: target ``k`` out of tolerance; 2: its joint change above ``max_jump``
    (``path`` then valid up to row ``k``)."""
    n_targets = targets.shape[0]
    path = np.empty((n_targets + 1, q_start.shape[0]))
    path[0] = q_start
    for k in range(n_targets):
        q, d, a = solve(base, pre, tail, axes, skew, skew2, prismatic, lower, upper, targets[k],
                        path[k], rest, ik_tol_m, ik_tol_rad, max_iterations, damping,
                        rot_weight_m, max_step, rest_gain)
        jump = np.abs(q - path[k]).max()
        if d > tol_m or a > tol_rad:
            return path, 1, k, d, a, jump
        if jump > max_jump:
            return path, 2, k, d, a, jump
        path[k + 1] = q
    return path, 0, -1, 0.0, 0.0, 0.0
