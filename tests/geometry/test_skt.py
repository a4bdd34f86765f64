"""skt_frames per waypoint against frames worked out by hand (columns x, y, z; g = −z):
frame i takes the motion arriving at ξ_i, from ξ_{i+1} to ξ_i; ξ_{T-1} reuses the segment
ξ_{T-1}→ξ_{T-2}; vertical segments take the nearest defined frame (ties: toward ξ_0)."""

import numpy as np
import pytest

from skt_lib.planning.trajectory import (
    executed_path, interpolate, keypoint_positions, max_point_step, resample, skt_frames,
)

# x = motion direction, y = x × (0, 0, −1), z = x × y — evaluated by hand:
# motion −x:              x = (−1, 0, 0),      y = (0, −1, 0), z = (0, 0, 1)
R_MINUS_X = np.array([[-1, 0, 0], [0, -1, 0], [0, 0, 1]], float)
# motion (−0.6, 0, −0.8) (down-tilted): y = (0, −0.6, 0)/0.6 = (0, −1, 0), z = (−0.8, 0, 0.6)
R_TILT_DOWN = np.array([[-0.6, 0, -0.8], [0, -1, 0], [-0.8, 0, 0.6]], float)
# motion −y:              x = (0, −1, 0),      y = (1, 0, 0),  z = (0, 0, 1)
R_MINUS_Y = np.array([[0, 1, 0], [-1, 0, 0], [0, 0, 1]], float)
# motion (0.6, 0, 0.8) (up-tilted, +x): y = (0, 0.6, 0)/0.6 = (0, 1, 0), z = (−0.8, 0, 0.6)
R_TILT_UP = np.array([[0.6, 0, -0.8], [0, 1, 0], [0.8, 0, 0.6]], float)


def _check(frames, positions, rotations):
    assert frames.shape == (len(positions), 4, 4)
    for i, (f, r) in enumerate(zip(frames, rotations)):
        assert f[:3, :3] == pytest.approx(r, abs=1e-12), f"waypoint {i}"
        assert f[:3, 3] == pytest.approx(positions[i], abs=1e-15), f"waypoint {i}"
        assert f[3] == pytest.approx([0, 0, 0, 1])


def test_frames_on_tilted_motion_per_waypoint():
    # ξ_0 first; execution runs ξ_4 → ξ_0. Motion arriving at ξ_i is ξ_i − ξ_{i+1}.
    pos = np.zeros((5, 3))
    pos[1] = pos[0] + [0.05, 0, 0]            # ξ_1→ξ_0: −x
    pos[2] = pos[1] + [0.03, 0, 0.04]         # ξ_2→ξ_1: (−0.6, 0, −0.8)
    pos[3] = pos[2] + [0, 0.02, 0]            # ξ_3→ξ_2: −y
    pos[4] = pos[3] + [-0.006, 0, -0.008]     # ξ_4→ξ_3: (0.6, 0, 0.8)
    pos += [0.1, -0.02, 0.3]
    # frame 4 (the start) reuses the segment leaving it
    _check(skt_frames(pos), pos, [R_MINUS_X, R_TILT_DOWN, R_MINUS_Y, R_TILT_UP, R_TILT_UP])


def test_frames_on_vertical_motion_per_waypoint():
    # vertical segments get the nearest defined frame; a tie goes toward ξ_0
    pos = np.zeros((6, 3))
    pos[1] = pos[0] + [0, 0, 0.02]            # segment 0 (ξ_1→ξ_0): straight down, undefined
    pos[2] = pos[1] + [0.03, 0, 0.04]         # segment 1: tilted down → R_TILT_DOWN
    pos[3] = pos[2] + [0, 0, 0.01]            # segment 2: straight down (tie 1 vs 3 → 1)
    pos[4] = pos[3] + [0.05, 0, 0]            # segment 3: −x → R_MINUS_X
    pos[5] = pos[4] + [0, 0, -0.03]           # segment 4: straight up → nearest: 3
    _check(skt_frames(pos), pos,  # frame 5 reuses segment 4 (undefined) → nearest: 3
           [R_TILT_DOWN, R_TILT_DOWN, R_TILT_DOWN, R_MINUS_X, R_MINUS_X, R_MINUS_X])
    # a purely vertical descent has no SKT frames
    with pytest.raises(ValueError, match="vertical"):
        skt_frames(np.array([[0, 0, 0], [0, 0, 0.01], [0, 0, 0.02]], float))
    # two waypoints: both frames from the single segment
    _check(skt_frames(pos[1:3]), pos[1:3], [R_TILT_DOWN, R_TILT_DOWN])


def test_executed_path_runs_start_to_hang_with_bounded_steps():
    pos = np.array([[0.0, 0, 0], [0.05, 0, 0], [0.08, 0, 0.04], [0.08, 0.02, 0.04]])
    path = executed_path(pos, 0.002, 0.03)
    assert path[0] == pytest.approx(skt_frames(pos)[-1]) and path[-1] == pytest.approx(skt_frames(pos)[0])
    # every original waypoint is on the path, in execution order
    hits = [int(np.argmin(np.linalg.norm(path[:, :3, 3] - p, axis=1))) for p in pos[::-1]]
    assert hits == sorted(hits) and all(np.allclose(path[h, :3, 3], p) for h, p in zip(hits, pos[::-1]))
    # no point within 3 cm of the keypoint moves more than 2 mm per pose
    d = np.linalg.norm(np.diff(path[:, :3, 3], axis=0), axis=1)
    ang = [np.arccos(np.clip((np.trace(a[:3, :3].T @ b[:3, :3]) - 1) / 2, -1, 1))
           for a, b in zip(path[:-1], path[1:])]
    assert (d + 0.03 * np.array(ang)).max() <= 0.002 + 1e-12
    # and the bound is tight: not needlessly dense
    assert (d + 0.03 * np.array(ang)).max() > 0.0015


def test_interpolate_keeps_frames_and_counts_steps():
    a, b = np.eye(4), np.eye(4)
    b[:3, 3] = [0.01, 0, 0]
    out = interpolate(np.stack([a, b]), 0.002, 0.0)
    assert len(out) == 6 and np.allclose(out[-1], b) and np.array_equal(out[0], a)
    assert np.allclose(np.diff(out[:, 0, 3]), 0.002)


def test_computed_in_float64_whatever_the_input_dtype():
    # magnitudes far apart, so float32 differences round where float64 ones are exact
    rng = np.random.default_rng(1)
    pos = (rng.uniform(size=(7, 3)) * 10.0 ** rng.integers(-3, 1, size=(7, 3))).astype(np.float32)
    wide = pos.astype(np.float64)
    assert np.array_equal(skt_frames(pos), skt_frames(wide))
    assert np.array_equal(resample(pos, 11), resample(wide, 11))
    assert np.array_equal(executed_path(pos, 0.002, 0.03), executed_path(wide, 0.002, 0.03))
    assert np.array_equal(executed_path(wide.tolist(), 0.002, 0.03),
                          executed_path(wide, 0.002, 0.03))


def test_resample_edge_cases_and_messages():
    two = np.array([[0.0, 0, 0], [0.04, 0, 0]])
    assert resample(two, 5) == pytest.approx(np.outer(np.linspace(0, 1, 5), [0.04, 0, 0]))
    assert np.array_equal(resample(two, 2), two)
    # a repeated first point (zero-length first segment) is not a zero-length trajectory
    rep = np.array([[0.0, 0, 0], [0.0, 0, 0], [0.03, 0, 0]])
    assert resample(rep, 4)[:, 0] == pytest.approx([0, 0.01, 0.02, 0.03])
    with pytest.raises(ValueError, match=r"^positions: zero-length trajectory$"):
        resample(np.zeros((3, 3)), 4)
    for bad in (two[:1], np.zeros((4, 4)), np.zeros(6)):
        with pytest.raises(ValueError, match=r"^positions: expected \(N>=2, 3\)"):
            resample(bad, 4)
    with pytest.raises(ValueError, match=r"^n: need at least 2 waypoints, got 1$"):
        resample(two, 1)
    with pytest.raises(ValueError, match=r"^positions: every segment is vertical; SKT "
                                         r"rotations are undefined$"):
        skt_frames(np.array([[0, 0, 0], [0, 0, 0.01]], float))


def test_interpolate_from_an_offset_start_and_between_equal_frames():
    a, b = np.eye(4), np.eye(4)
    a[:3, 3], b[:3, 3] = [0.3, 0.2, 0.1], [0.3, 0.2, 0.104]
    out = interpolate(np.stack([a, b]), 0.001, 0.0)
    assert len(out) == 5 and np.allclose(np.diff(out[:, 2, 3]), 0.001)
    same = interpolate(np.stack([a, a]), 0.001, 0.05)
    assert len(same) == 2 and np.array_equal(same[0], a) and np.allclose(same[1], a)


def test_keypoint_positions_by_hand():
    poses = np.tile(np.eye(4), (2, 1, 1))
    poses[1, :3, :3] = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]  # 90° about z
    poses[1, :3, 3] = [0.1, 0.2, 0.3]
    kp = np.array([0.01, 0.02, 0.03])
    assert keypoint_positions(poses, kp) == pytest.approx(
        np.array([[0.01, 0.02, 0.03], [0.1 - 0.02, 0.2 + 0.01, 0.33]]))


def test_max_point_step_by_hand():
    poses = np.tile(np.eye(4), (3, 1, 1))
    poses[1, :3, 3] = [0.003, 0.0, 0.0]
    poses[2, :3, :3] = [[0, -1, 0], [1, 0, 0], [0, 0, 1]]  # 90° about z, back at the origin
    pts = np.array([[0.0, 0.0, 0.0], [0.01, 0.0, 0.0]])
    # 0→1: both move 3 mm; 1→2: (0.013, 0, 0) → (0, 0.01, 0): sqrt(0.013² + 0.01²)
    assert max_point_step(poses, pts) == pytest.approx(np.hypot(0.013, 0.01))
    assert max_point_step(poses[:2], pts) == pytest.approx(0.003)
