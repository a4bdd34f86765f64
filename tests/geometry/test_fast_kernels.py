"""The fast kernels of planning and simulation are bit-equal to the numpy / scipy calls they
replace: a faster planner that changed one bit could grow another tree, and a faster trial
could tip a contact, so equality is exact here, not approximate."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from skt_lib.geometry.se3 import matrix_to_quat, matrix_to_quat_naive
from skt_lib.geometry.skt import (
    cross3,
    interpolate,
    interpolate_naive,
    minimal_rotation,
    minimal_rotation_naive,
    rotvec_matrix,
    skt_frames,
    skt_frames_naive,
)
from skt_lib.planning.frames import limit_direction


def _unit_rows(rng, n):
    v = rng.standard_normal((n, 3))
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def test_cross3_is_numpys_cross_bit_for_bit():
    rng = np.random.default_rng(0)
    a, b = rng.standard_normal((2, 5000, 3)) * rng.choice([1e-9, 1.0, 1e6], (2, 5000, 1))
    for x, y in zip(a, b):
        assert np.array_equal(cross3(x, y), np.cross(x, y))
    assert np.array_equal(cross3(a[0], (0.0, 0.0, 1.0)), np.cross(a[0], [0.0, 0.0, 1.0]))
    assert np.array_equal(cross3(-np.zeros(3), np.ones(3)), np.cross(-np.zeros(3), np.ones(3)))
    assert np.array_equal(cross3((0.0, 0.0, 1.0), a[0]), np.cross([0.0, 0.0, 1.0], a[0]))
    # float32 vectors are multiplied in float64 (as plain floats), not rounded to float32
    x, y = a[:2].astype(np.float32)
    for u, v in ((x, y), (x, y.astype(np.float64)), (x.astype(np.float64), y)):
        assert np.array_equal(cross3(u, v), np.cross(np.float64(u), np.float64(v)))


def test_rotvec_matrix_is_scipys_bit_for_bit_across_the_taylor_switch():
    rng = np.random.default_rng(1)
    n = 0
    for scale in (1e-7, 1e-4, 9.9e-4, 1e-3, 1.01e-3, 0.3, 3.1):
        for v in rng.standard_normal((3000, 3)) / np.sqrt(3) * scale:
            assert np.array_equal(rotvec_matrix(*v), Rotation.from_rotvec(v).as_matrix()), v
            n += 1
    assert np.array_equal(rotvec_matrix(0.0, 0.0, 0.0), np.eye(3))
    assert n == 21000
    # exactly at the switch (scipy's series, ``angle <= 1e-3``; its sine differs in the last bit)
    for v in ((1e-3, 0.0, 0.0), (0.0, -1e-3, 0.0), (6e-4, 0.0, 8e-4)):
        assert np.array_equal(rotvec_matrix(*v), Rotation.from_rotvec(v).as_matrix()), v


def test_minimal_rotation_is_the_naive_one_bit_for_bit():
    rng = np.random.default_rng(2)
    a = _unit_rows(rng, 4000)
    # general pairs, nearly parallel, nearly opposite, exactly equal and exactly opposite
    near = a + rng.standard_normal(a.shape) * rng.choice([1e-13, 1e-8, 1e-3], (len(a), 1))
    cases = [(_unit_rows(rng, 4000), "random"), (near / np.linalg.norm(near, axis=1)[:, None],
                                                 "near"), (-a, "opposite"), (a.copy(), "equal")]
    for b, label in cases:
        for x, y in zip(a, b):
            side = np.cross(x, [0.0, 0.0, 1.0])
            side /= np.linalg.norm(side)
            assert np.array_equal(minimal_rotation(x, y, side),
                                  minimal_rotation_naive(x, y, side)), label


@pytest.mark.parametrize("fn", [minimal_rotation, minimal_rotation_naive])
def test_minimal_rotation_turns_by_1e12_rad_not_the_identity(fn):
    """|a × b| = 1e-12 exactly (the threshold, which is exclusive): still the 1e-12 rad turn
    about z that takes a onto b, not the identity."""
    a, b = np.array([1.0, 0.0, 0.0]), np.array([1.0, 1e-12, 0.0])  # |b| rounds to 1
    assert np.linalg.norm(np.cross(a, b)) == 1e-12
    r = fn(a, b, np.array([0.0, 1.0, 0.0]))
    assert np.array_equal(r, Rotation.from_rotvec([0.0, 0.0, 1e-12]).as_matrix())
    assert r[1, 0] == 1e-12 and np.array_equal(r @ a, b)


def _limit_direction_naive(d, prev, max_turn):
    """The planner's step limit as it was written with ``np.cross``."""
    d = d / np.linalg.norm(d)
    if float(np.arccos(np.clip(np.dot(d, prev), -1.0, 1.0))) > max_turn:
        axis = np.cross(prev, d)
        if np.linalg.norm(axis) < 1e-9:
            axis = np.cross(prev, [0.0, 0.0, 1.0])
            if np.linalg.norm(axis) < 1e-9:
                axis = np.array([0.0, 1.0, 0.0])
        axis = axis / np.linalg.norm(axis)
        d = prev * np.cos(max_turn) + np.cross(axis, prev) * np.sin(max_turn)
    return d / np.linalg.norm(d)


def test_limit_direction_is_the_np_cross_version_bit_for_bit():
    rng = np.random.default_rng(3)
    prev = _unit_rows(rng, 3000)
    d = np.vstack([rng.standard_normal((1000, 3)), -prev[1000:2000],
                   prev[2000:] + 1e-3 * rng.standard_normal((1000, 3))])
    d[5] = -np.array([0.0, 0.0, 1.0]) * 2  # opposite to a vertical prev: the y-axis fallback
    prev[5] = [0.0, 0.0, 1.0]
    for x, p in zip(d, prev):
        for turn in (np.radians(10.0), np.radians(45.0)):
            assert np.array_equal(limit_direction(x, p, turn), _limit_direction_naive(x, p, turn))


def test_frames_still_equal_their_reference_with_the_fast_kernels():
    rng = np.random.default_rng(4)
    for _ in range(50):
        p = np.cumsum(rng.standard_normal((20, 3)) * 0.01, axis=0)
        np.testing.assert_allclose(skt_frames(p), skt_frames_naive(p), atol=1e-9)


def _random_walk(rng, n, step):
    return np.cumsum(rng.standard_normal((n, 3)) * step, axis=0)


def test_interpolate_is_one_slerp_per_segment_bit_for_bit():
    rng = np.random.default_rng(5)
    n_poses = 0
    for i in range(60):
        p = _random_walk(rng, int(rng.integers(2, 45)), [0.02, 0.005, 0.001][i % 3])
        if i % 7 == 0:
            p = np.vstack([p, p[-1:] + [1e-3, 0.0, 0.0]])
        frames = skt_frames(p)[::-1]
        for step, radius in ((0.002, 0.08), (0.0005, 0.03), (0.05, 0.0)):
            fast, naive = interpolate(frames, step, radius), interpolate_naive(frames, step, radius)
            assert fast.shape == naive.shape
            assert np.array_equal(fast, naive), (i, step, radius)
            n_poses += len(fast)
    # two equal frames: one pose added, the frame itself
    f = np.tile(np.eye(4), (2, 1, 1))
    assert np.array_equal(interpolate(f, 0.002, 0.05), interpolate_naive(f, 0.002, 0.05))
    assert n_poses > 10000


def test_matrix_to_quat_is_scipys_bit_for_bit_and_falls_back_off_rotations():
    rng = np.random.default_rng(6)
    rots = Rotation.random(4000, random_state=7).as_matrix()
    special = [np.eye(3), np.diag([1.0, -1.0, -1.0]), np.diag([-1.0, 1.0, -1.0]),
               np.diag([-1.0, -1.0, 1.0]), Rotation.from_euler("z", 90, degrees=True).as_matrix()]
    for eps in (0.0, 1e-15, 5e-14, 2e-13, 1e-9, 1e-3):  # past 1e-13: scipy's own path
        for m in [*(rots + rng.standard_normal(rots.shape) * eps), *special]:
            assert np.array_equal(matrix_to_quat(m), matrix_to_quat_naive(m)), (eps, m)
    assert np.array_equal(matrix_to_quat(rots[:10]), matrix_to_quat_naive(rots[:10]))
    with pytest.raises(ValueError, match="determinant"):
        matrix_to_quat(np.diag([1.0, 1.0, -1.0]))
