"""SE(3) helpers. Quaternions are xyzw (PyBullet and scipy order); rotations (3, 3)."""

import math

import numpy as np
from scipy.spatial.transform import Rotation

GRAVITY_DIR = np.array([0.0, 0.0, -1.0])  # unit gravity, support and world frames
_EYE = np.eye(3)


def quat_to_matrix(q) -> np.ndarray:
    return Rotation.from_quat(np.asarray(q, dtype=np.float64)).as_matrix()


#: :func:`matrix_to_quat` converts a single matrix itself when ``M Mᵀ`` is within this of the
#: identity: scipy converts such a matrix as it is (it orthogonalizes first only beyond
#: 1e-12), with the formulas below in the same order, so the quaternion has the same bits.
_ORTHOGONAL_TOL = 1e-13


def matrix_to_quat(m) -> np.ndarray:
    """xyzw quaternion(s) of rotation matrices ``(3, 3)`` or ``(N, 3, 3)``: scipy's
    ``Rotation.from_matrix(m).as_quat()``, bit for bit (:func:`matrix_to_quat_naive`); a single
    orthogonal matrix without scipy's per-call overhead (about 10× faster; simulation
    converts one pose per step)."""
    m = np.asarray(m, dtype=np.float64)
    if m.shape != (3, 3) or np.abs(m @ m.T - _EYE).max() >= _ORTHOGONAL_TOL:
        return matrix_to_quat_naive(m)
    (a, b, c), (d, e, f), (g, h, i) = rows = m.tolist()
    if a * (e * i - f * h) - b * (d * i - f * g) + c * (d * h - e * g) <= 0.5:
        return matrix_to_quat_naive(m)  # not a rotation: scipy raises
    trace = a + e + i
    decision = (a, e, i, trace)
    k = decision.index(max(decision))  # the first largest, as scipy's argmax
    if k == 3:
        q = [h - f, c - g, d - b, 1 + trace]
    else:
        j, n = (k + 1) % 3, (k + 2) % 3
        q = [0.0] * 4
        q[k] = 1 - trace + 2 * rows[k][k]
        q[j] = rows[j][k] + rows[k][j]
        q[n] = rows[n][k] + rows[k][n]
        q[3] = rows[n][j] - rows[j][n]
    norm = math.sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3])
    return np.array([q[0] / norm, q[1] / norm, q[2] / norm, q[3] / norm])


def matrix_to_quat_naive(m) -> np.ndarray:
    """Reference for :func:`matrix_to_quat`: scipy."""
    return Rotation.from_matrix(np.asarray(m, dtype=np.float64)).as_quat()


def pose_matrix(position, quat) -> np.ndarray:
    """4×4 homogeneous transform from a position (3,) and an xyzw quaternion."""
    t = np.eye(4)
    t[:3, :3] = quat_to_matrix(quat)
    t[:3, 3] = position
    return t


def matrix_pose(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return np.asarray(t[:3, 3], dtype=np.float64), matrix_to_quat(t[:3, :3])


def invert(t: np.ndarray) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = t[:3, :3].T
    out[:3, 3] = -t[:3, :3].T @ t[:3, 3]
    return out


def transform_points(t: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply a 4×4 transform to ``points (N, 3)``."""
    return np.asarray(points) @ t[:3, :3].T + t[:3, 3]


def skt_rotation(moving_dir, gravity=GRAVITY_DIR) -> np.ndarray:
    """The SKT rotation rule (paper §III-A): x = unit moving direction, y = x × g, z = x × y.

    Columns are the axes. Raises ``ValueError`` when the motion is (nearly) vertical, where
    the rule is undefined.
    """
    x = np.asarray(moving_dir, dtype=np.float64)
    norm = np.linalg.norm(x)
    if not np.isfinite(norm) or norm < 1e-12:
        raise ValueError("moving_dir: zero or non-finite")
    x = x / norm
    y = np.cross(x, np.asarray(gravity, dtype=np.float64))
    if np.linalg.norm(y) < 1e-6:
        raise ValueError("moving_dir: parallel to gravity, the SKT rule is undefined")
    y /= np.linalg.norm(y)
    z = np.cross(x, y)
    return np.stack([x, y, z], axis=1)


def random_rotation_small(rng: np.random.Generator, max_deg: float) -> np.ndarray:
    """A rotation about a uniformly random axis by an angle uniform in [0, max_deg]."""
    axis = rng.normal(size=3)
    axis /= np.linalg.norm(axis)
    return Rotation.from_rotvec(axis * np.radians(rng.uniform(0, max_deg))).as_matrix()
