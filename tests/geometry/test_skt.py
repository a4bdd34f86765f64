"""The SKT contract (docs/design.md §3): rotation-minimizing frames anchored at the hang, against
frames worked out by hand (columns x, y, z; g = −z), the per-step reference, closed forms
(a helix's holonomy) and the rule where they must equal it; resampling by travel and turning;
the executed path."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from skt_lib.geometry.skt import (
    _EPS_LEN, _EPS_VERTICAL, TURN_RADIUS_M, arc_length, executed_path, interpolate,
    keypoint_positions, max_point_step, motion_directions, resample, rule_frames, skt_frames,
    skt_frames_naive, turning_length,
)

# x = motion direction, y = x × (0, 0, −1), z = x × y — evaluated by hand:
# motion −x:              x = (−1, 0, 0),      y = (0, −1, 0), z = (0, 0, 1)
R_MINUS_X = np.array([[-1, 0, 0], [0, -1, 0], [0, 0, 1]], float)
# motion (−0.6, 0, −0.8) (down-tilted): y = (0, −0.6, 0)/0.6 = (0, −1, 0), z = (−0.8, 0, 0.6)
R_TILT_DOWN = np.array([[-0.6, 0, -0.8], [0, -1, 0], [-0.8, 0, 0.6]], float)
# motion straight down (0, 0, −1), transported from R_TILT_DOWN about y: z = (−1, 0, 0)
R_DOWN = np.array([[0, 0, -1], [0, -1, 0], [-1, 0, 0]], float)
# motion −y, transported from R_MINUS_X by a quarter turn about +z: y = (1, 0, 0)
R_MINUS_Y = np.array([[0, 1, 0], [-1, 0, 0], [0, 0, 1]], float)


def _check(frames, positions, rotations):
    assert frames.shape == (len(positions), 4, 4)
    for i, (f, r) in enumerate(zip(frames, rotations)):
        assert f[:3, :3] == pytest.approx(r, abs=1e-12), f"waypoint {i}"
        assert f[:3, 3] == pytest.approx(positions[i], abs=1e-15), f"waypoint {i}"
        assert f[3] == pytest.approx([0, 0, 0, 1])


def test_frames_by_hand_through_a_vertical_descent():
    """Down a vertical stretch (where the rule is undefined) the frame keeps its roll, and
    ξ_0 gets the rule's frame of the arrival."""
    pos = np.zeros((5, 3))
    pos[1] = pos[0] + [0.05, 0, 0]            # ξ_1→ξ_0: −x (arrival: the anchor)
    pos[2] = pos[1] + [0.03, 0, 0.04]         # ξ_2→ξ_1: (−0.6, 0, −0.8)
    pos[3] = pos[2] + [0, 0, 0.02]            # ξ_3→ξ_2: straight down
    pos[4] = pos[3] + [0, 0, 0.03]            # ξ_4→ξ_3: straight down (the start reuses it)
    pos += [0.1, -0.02, 0.3]
    _check(skt_frames(pos), pos, [R_MINUS_X, R_TILT_DOWN, R_DOWN, R_DOWN, R_DOWN])
    assert np.isnan(rule_frames(pos)[2:, :3, 1]).all()  # the rule has no frame there


def test_frames_by_hand_where_the_horizontal_motion_turns_back():
    """Horizontal motion turning back (−x, then −y, then +x): the transported frame turns
    with the motion, y (0,−1,0) → (1,0,0) → (0,1,0), z stays up — as the rule says there."""
    pos = np.zeros((4, 3))
    pos[1] = pos[0] + [0.02, 0, 0]            # −x
    pos[2] = pos[1] + [0, 0.02, 0]            # −y
    pos[3] = pos[2] + [-0.02, 0, 0]           # +x
    r_plus_x = np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1]], float)
    _check(skt_frames(pos), pos, [R_MINUS_X, R_MINUS_Y, r_plus_x, r_plus_x])
    # horizontal motion only: the rule says the same
    assert np.allclose(skt_frames(pos), rule_frames(pos), atol=1e-12)


def test_vertical_arrival_takes_the_first_defined_rule_frame_outward():
    pos = np.zeros((4, 3))
    pos[1] = pos[0] + [0, 0, 0.02]            # arriving straight down: no rule frame at ξ_0
    pos[2] = pos[1] + [0.03, 0, 0.04]         # R_TILT_DOWN: the anchor
    pos[3] = pos[2] + [0.05, 0, 0]            # −x
    _check(skt_frames(pos), pos, [R_DOWN, R_TILT_DOWN, R_MINUS_X, R_MINUS_X])
    with pytest.raises(ValueError, match="vertical"):
        skt_frames(np.array([[0, 0, 0], [0, 0, 0.01], [0, 0, 0.02]], float))


def _random_paths(seed: int, n: int):
    rng = np.random.default_rng(seed)
    for _ in range(n):
        k = int(rng.integers(2, 50))
        p = np.cumsum(rng.normal(size=(k, 3)) * 0.01, axis=0)
        if rng.random() < 0.3:  # zero-length segments
            i = int(rng.integers(1, k))
            p[i] = p[i - 1]
        if rng.random() < 0.3:  # vertical segments
            i = int(rng.integers(1, k))
            p[i, :2] = p[i - 1, :2]
        if rng.random() < 0.1:  # a full reversal
            i = int(rng.integers(1, k - 1)) if k > 2 else 1
            p[i + 1:] = p[i] - (p[i + 1:] - p[i]) if k > 2 else p[i + 1:]
        yield p


def test_fast_frames_equal_the_per_step_minimal_rotations_on_random_paths():
    n = 0
    for p in _random_paths(0, 300):
        try:
            fast = skt_frames(p)
        except ValueError:
            with pytest.raises(ValueError):
                skt_frames_naive(p)
            continue
        n += 1
        np.testing.assert_allclose(fast, skt_frames_naive(p), atol=1e-9)
        r = fast[:, :3, :3]
        np.testing.assert_allclose(np.einsum("nji,njk->nik", r, r), np.broadcast_to(np.eye(3), r.shape),
                                   atol=1e-9)
        assert np.allclose(np.linalg.det(r), 1.0)
    assert n > 250


def test_continuity_no_frame_step_larger_than_the_turn_of_the_motion():
    for p in _random_paths(1, 300):
        try:
            f = skt_frames(p)
        except ValueError:
            continue
        x = f[:, :3, 0]
        turn = np.arccos(np.clip(np.sum(x[1:] * x[:-1], axis=1), -1, 1))
        rel = np.einsum("nji,njk->nik", f[:-1, :3, :3], f[1:, :3, :3])
        step = np.arccos(np.clip((np.trace(rel, axis1=1, axis2=2) - 1) / 2, -1, 1))
        assert np.all(step <= turn + 1e-7)


def test_planar_paths_equal_the_rule():
    t = np.linspace(0.0, 1.0, 60)
    # in a vertical plane (not crossing the vertical): an arc over an upturned tip
    vertical_plane = np.stack([0.1 * t, np.zeros_like(t), 0.04 * np.sin(2.5 * t)], axis=1)
    # horizontal, turning both ways
    horizontal = np.stack([0.05 * np.cos(3 * t), 0.05 * np.sin(5 * t), np.full_like(t, 0.2)], axis=1)
    for p in (vertical_plane, horizontal):
        np.testing.assert_allclose(skt_frames(p), rule_frames(p), atol=1e-9)
    # a rotated vertical plane as well
    rot = Rotation.from_rotvec([0, 0, 0.7]).as_matrix()
    p = vertical_plane @ rot.T
    np.testing.assert_allclose(skt_frames(p), rule_frames(p), atol=1e-9)


def test_helix_roll_is_the_holonomy_of_its_closed_form():
    """After one turn of a helix the tangent is back where it started, and parallel transport
    has rolled the frame about it by the solid angle the tangent swept: 2π(1 − cos α), α the
    tangent's angle to the helix axis. The rule frame (y kept horizontal) comes back
    unrolled."""
    a, b = 0.05, 0.02
    phi = np.linspace(0.0, 2 * np.pi, 4001)
    pos = np.stack([a * np.cos(phi), a * np.sin(phi), b * phi], axis=1)[::-1]  # ξ_0: the top
    f = skt_frames(pos)
    cos_alpha = b / np.hypot(a, b)
    expected = 2 * np.pi * (1 - cos_alpha)
    assert np.allclose(f[0, :3, 0], f[-1, :3, 0], atol=3e-3)  # the same tangent after one turn
    y0, y1 = f[0, :3, 1], f[-1, :3, 1]
    roll = np.arctan2(np.dot(np.cross(y0, y1), f[0, :3, 0]), np.dot(y0, y1))
    wrap = lambda v: (v + np.pi) % (2 * np.pi) - np.pi  # noqa: E731
    assert min(abs(wrap(roll - expected)), abs(wrap(roll + expected))) < 5e-3
    assert abs(wrap(roll)) > 1.0  # and it is a real roll, not nothing
    rule = rule_frames(pos)
    assert np.allclose(rule[0, :3, :3], rule[-1, :3, :3], atol=3e-3)


def test_resample_puts_waypoints_where_the_object_turns():
    """A 120° bend of 2 mm radius between two straight 5 cm legs: by arc length alone it gets
    at most one of 20 waypoints; counted with turning, several — in proportion to its weight."""
    th = np.linspace(0, np.radians(120), 200)
    r = 0.002
    bend = np.stack([r * np.sin(th), np.zeros_like(th), r * (1 - np.cos(th))], axis=1)
    leg_in = np.stack([np.linspace(-0.05, 0, 100)[:-1], np.zeros(99), np.zeros(99)], axis=1)
    d = np.array([np.cos(np.radians(120)), 0.0, np.sin(np.radians(120))])
    leg_out = bend[-1] + np.outer(np.linspace(0, 0.05, 100)[1:], d)
    path = np.vstack([leg_in, bend, leg_out])
    in_bend = lambda w: int(np.sum(np.linalg.norm(w - [0.0, 0.0, r], axis=1) <= r + 1e-6))  # noqa: E731
    assert in_bend(resample(path, 20, turn_radius_m=0.0)) <= 1
    turned = resample(path, 20)
    weight = TURN_RADIUS_M * np.radians(120) / (TURN_RADIUS_M * np.radians(120) + 0.1 + r * np.radians(120))
    assert in_bend(turned) >= int(np.floor(weight * 19)) - 1 >= 5
    # the turning length is arc length plus the turn at the stated radius
    s = turning_length(path)
    assert s[-1] == pytest.approx(0.1 + r * np.radians(120) + TURN_RADIUS_M * np.radians(120), rel=1e-3)
    # straight paths: plain arc-length spacing
    line = np.outer(np.linspace(0, 1, 7) ** 2, [0.1, 0.02, -0.03])
    np.testing.assert_allclose(resample(line, 5), np.outer(np.linspace(0, 1, 5), [0.1, 0.02, -0.03]),
                               atol=1e-12)


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
    # the round trip through executed_path: the frames at the waypoints are skt_frames'
    pos = resample(np.array([[0.0, 0, 0], [0.05, 0, 0], [0.08, 0.01, 0.04], [0.1, 0.0, 0.1]]), 9)
    path = executed_path(pos, 0.001, 0.03)
    hits = [int(np.argmin(np.linalg.norm(path[:, :3, 3] - p, axis=1))) for p in pos[::-1]]
    np.testing.assert_allclose(path[hits], skt_frames(pos)[::-1], atol=1e-9)
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


def test_arc_length_by_hand():
    pos = np.array([[0.0, 0, 0], [0.75, 1.0, 0], [0.75, 1.0, 0.5], [0.75, 1.0, 0.5]])
    assert np.array_equal(arc_length(pos), [0.0, 1.25, 1.75, 1.75])


@pytest.mark.parametrize("frames_fn", [skt_frames, skt_frames_naive])
def test_both_frame_functions_by_hand_through_two_vertical_segments_and_a_reversal(frames_fn):
    """The reference is held to the same frames as the fast version: anchored two waypoints
    out (the first two arrivals are vertical), and over a full reversal the half turn about y
    (y kept, x and z turned over)."""
    pos = np.zeros((5, 3))
    pos[1] = pos[0] + [0, 0, 0.02]            # down
    pos[2] = pos[1] + [0, 0, 0.03]            # down
    pos[3] = pos[2] + [0.03, 0, 0.04]         # R_TILT_DOWN: the anchor
    pos[4] = pos[3] + [0.05, 0, 0]            # −x
    _check(frames_fn(pos), pos, [R_DOWN, R_DOWN, R_TILT_DOWN, R_MINUS_X, R_MINUS_X])
    back = np.array([[0.0, 0, 0], [0.02, 0, 0], [0.0, 0, 0]])  # −x into the hang, +x before
    over = np.diag([1.0, -1.0, -1.0])
    _check(frames_fn(back), back, [R_MINUS_X, over, over])


@pytest.mark.parametrize("frames_fn", [skt_frames, skt_frames_naive])
def test_the_anchor_frame_is_the_rule_frame_bit_for_bit(frames_fn):
    """Transport starts from the rule's frame at the anchor and never comes back to it: the
    anchor's rotation is the rule's exactly (an anchor recomputed by transporting there and
    back would differ by rounding)."""
    rng = np.random.default_rng(5)
    for _ in range(10):
        p = np.cumsum(rng.normal(size=(6, 3)) * 0.01, axis=0)
        down = p.copy()
        down[0] = p[1] - [0, 0, 0.01]  # arriving straight down: anchored at ξ_1
        for anchor, pos in ((0, p), (1, down)):
            np.testing.assert_array_equal(frames_fn(pos)[anchor], rule_frames(pos)[anchor])


def test_thresholds_are_inclusive_where_documented():
    """A segment of exactly ``_EPS_LEN`` has a direction; a motion whose horizontal share is
    exactly ``_EPS_VERTICAL`` has a rule frame."""
    pos = np.array([[0.0, 0, 0], [0.0, _EPS_LEN, 0], [0.01, _EPS_LEN, 0]])
    assert np.array_equal(motion_directions(pos), [[0.0, -1, 0], [-1.0, 0, 0], [-1.0, 0, 0]])
    h = 1.0000000000005e-06  # (−h, 0, −1) normalised: horizontal share exactly 1e-6
    pos = np.array([[0.0, 0, 0], [h, 0, 1.0], [h + 0.01, 0, 1.0]])
    x = motion_directions(pos)[0]
    assert np.linalg.norm(np.cross(x, [0.0, 0, -1])[None], axis=1)[0] == _EPS_VERTICAL
    r = rule_frames(pos)[0, :3, :3]  # the rule's frame of that motion: y = (0, −1, 0)
    assert np.array_equal(r[:, 0], x) and np.array_equal(r[:, 1], [0.0, -1, 0])
    assert np.array_equal(r[:, 2], np.cross(x, [0.0, -1, 0]))


def test_undefined_and_underflowing_rule_frames_warn_nothing():
    """Vertical motion (0/0) and a horizontal share whose square underflows (x/0) give NaN
    rule frames silently, as documented, not numpy RuntimeWarnings."""
    import warnings

    vertical = np.array([[0.0, 0, 0], [0, 0, 0.02], [0.03, 0, 0.06]])
    tiny = np.array([[0.0, 0, 0], [1e-172, 0, 0.01], [0.03, 0, 0.05]])  # share 1e-170: y_norm 0
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        for pos in (vertical, tiny):
            r = rule_frames(pos)
            assert np.isnan(r[0, :3, 1:3]).all() and np.isfinite(r[1]).all()
            assert np.isfinite(skt_frames(pos)).all()


def test_turning_length_where_unit_directions_dot_past_one():
    """Along a direction whose normalised square rounds to 1 + 2⁻⁵², a straight path turns by
    0 and a reversal by π — never NaN."""
    v = np.array([0.90347018, 0.0940123, -0.74349925])
    t = motion_directions(np.array([v, [0.0, 0, 0]]))[0]
    assert t @ t > 1.0  # the case at hand
    line = np.array([[0.0, 0, 0], v, 2 * v])
    assert np.array_equal(turning_length(line), arc_length(line))
    back = np.array([[0.0, 0, 0], v, [0.0, 0, 0]])
    n = np.linalg.norm(v)
    assert turning_length(back) == pytest.approx([0.0, n + TURN_RADIUS_M * np.pi / 2,
                                                  2 * n + TURN_RADIUS_M * np.pi], rel=1e-14)


def test_zero_length_frames_message():
    with pytest.raises(ValueError, match=r"^positions: zero-length trajectory; SKT frames are "
                                         r"undefined$"):
        skt_frames(np.zeros((3, 3)))


def test_interpolate_widens_float32_frames_first():
    """A float32 1e-8 offset vanishes in a float32 difference (1 − 1e-8 rounds to 1): the
    pose count is the float64 one, 4 steps of just under 0.25, not 5."""
    a, b = np.eye(4, dtype=np.float32), np.eye(4, dtype=np.float32)
    a[0, 3], b[0, 3] = 1e-8, 1.0
    frames = np.stack([a, b])
    out = interpolate(frames, 0.2499999999, 0.0)
    assert len(out) == 5 and out.dtype == np.float64
    assert np.array_equal(out, interpolate(frames.astype(np.float64), 0.2499999999, 0.0))
