"""OmniHang-style baseline (:mod:`skt_lib.eval.omnihang`) on synthetic scenes: a ring
hung on a horizontal peg sticking out of the wall, seen as points.

Scene (support frame: wall x = 0, free space x > 0, z up): the peg is a cylinder of radius
5 mm along +x from the wall to x = 8 cm, axis at y = z = 0, sampled on its surface. The ring
is a torus (major radius 2 cm, minor 3 mm) with its axis along the support x axis; the
keypoint is the ring's inner top. At the hang the keypoint rests on the peg's top at
x = 4 cm, so the object touches the cloud there and the planner must lift the release point.
The hanging frame is the SKT rule's frame for motion −x (threading the ring onto the peg).
"""

import numpy as np
import pytest

from skt_lib.eval.omnihang import (
    CloudClearance,
    OmniHangSettings,
    _densify,
    _poses,
    plan_omnihang,
)
from skt_lib.geometry.skt import arc_length

PEG_R, PEG_LEN = 0.005, 0.08
RING_R, TUBE_R = 0.02, 0.003
R_MINUS_X = np.array([[-1, 0, 0], [0, -1, 0], [0, 0, 1]], float)  # rule frame, motion −x
T = 40


def peg_cloud(spacing: float = 0.002) -> np.ndarray:
    """Surface points of the peg (side and end cap), (N, 3), support frame."""
    xs = np.arange(0.0, PEG_LEN + 1e-9, spacing)
    th = np.linspace(0, 2 * np.pi, int(np.ceil(2 * np.pi * PEG_R / spacing)), endpoint=False)
    x, t = np.meshgrid(xs, th, indexing="ij")
    side = np.stack([x.ravel(), PEG_R * np.cos(t.ravel()), PEG_R * np.sin(t.ravel())], 1)
    r, t = np.meshgrid(np.arange(spacing, PEG_R, spacing), th, indexing="ij")
    cap = np.stack([np.full(r.size, PEG_LEN), (r * np.cos(t)).ravel(), (r * np.sin(t)).ravel()], 1)
    return np.vstack([side, cap, [[PEG_LEN, 0.0, 0.0]]])


def ring_points(spacing: float = 0.002) -> np.ndarray:
    """Torus surface samples in the keypoint frame: axis along x, keypoint at the inner top,
    so the ring's centre is at z = −(RING_R − TUBE_R)."""
    u = np.linspace(0, 2 * np.pi, int(np.ceil(2 * np.pi * RING_R / spacing)), endpoint=False)
    v = np.linspace(0, 2 * np.pi, int(np.ceil(2 * np.pi * TUBE_R / spacing)), endpoint=False)
    u, v = (a.ravel() for a in np.meshgrid(u, v, indexing="ij"))
    rho = RING_R + TUBE_R * np.cos(v)
    pts = np.stack([TUBE_R * np.sin(v), rho * np.cos(u), rho * np.sin(u)], 1)
    return pts - [0.0, 0.0, RING_R - TUBE_R]


def hang_pose(x: float = 0.04) -> np.ndarray:
    h = np.eye(4)
    h[:3, :3] = R_MINUS_X
    h[:3, 3] = [x, 0.0, PEG_R]  # the ring's inner top on the peg's top
    return h


def plane_points(x: float, ys, zs, spacing: float = 0.002) -> np.ndarray:
    """A dense rectangle of points in the plane x = const."""
    y, z = np.meshgrid(np.arange(*ys, spacing), np.arange(*zs, spacing), indexing="ij")
    return np.stack([np.full(y.size, x), y.ravel(), z.ravel()], 1)


def sphere_points(centre, radius: float, spacing: float = 0.0015) -> np.ndarray:
    """A dense Fibonacci sphere of points."""
    n = int(np.ceil(4 * np.pi * radius**2 / spacing**2))
    i = np.arange(n) + 0.5
    phi, theta = np.arccos(1 - 2 * i / n), np.pi * (1 + 5**0.5) * i
    d = np.stack([np.cos(theta) * np.sin(phi), np.sin(theta) * np.sin(phi), np.cos(phi)], 1)
    return np.asarray(centre) + radius * d


def dense_clearance(cloud, obj, positions, step=0.0005) -> float:
    """Clearance of the output re-interpolated densely, at the hanging orientation."""
    return CloudClearance(cloud, obj).clearance(_poses(R_MINUS_X, _densify(positions, step)))


def guaranteed(positions, s: OmniHangSettings) -> float:
    """The module's guarantee for a solved plan: clearance_m − (spacing + check_step_m) / 2."""
    spacing = arc_length(positions)[-1] / (len(positions) - 1)
    return s.clearance_m - (spacing + s.check_step_m) / 2


@pytest.fixture(scope="module")
def scene():
    return peg_cloud(), ring_points(), hang_pose()


@pytest.fixture(scope="module")
def detour_scene(scene):
    cloud, obj, hang = scene
    # a screen across the straight approach, in front of the peg's end
    screen = plane_points(0.11, (-0.05, 0.05), (-0.03, 0.09))
    return np.vstack([cloud, screen]), obj, hang


def test_cloud_clearance_matches_brute_force():
    rng = np.random.default_rng(0)
    cloud, obj = rng.uniform(0.0, 0.1, (300, 3)), rng.normal(0, 0.01, (50, 3))
    poses = _poses(R_MINUS_X, rng.uniform(0.0, 0.1, (7, 3)))
    pts = np.einsum("mij,kj->mki", poses[:, :3, :3], obj) + poses[:, None, :3, 3]
    naive = min(np.linalg.norm(pts.reshape(-1, 1, 3) - cloud[None], axis=2).min(),
                pts[..., 0].min())
    checker = CloudClearance(cloud, obj, clearance_m=0.003)
    assert checker.clearance(poses) == pytest.approx(naive, abs=1e-12)
    assert [checker.clearance(p) for p in poses] == pytest.approx(
        [min(np.linalg.norm(q[:, None] - cloud[None], axis=2).min(), q[:, 0].min()) for q in pts])
    assert checker.collides(poses) == (naive < 0.003)
    # collides (with its bounding-sphere shortcut) agrees with clearance, near and far
    offsets = np.linspace(-0.2, 0.2, 81)
    centre = cloud.mean(0)
    for k, o in enumerate(offsets):
        rot = np.linalg.qr(rng.normal(size=(3, 3)))[0]
        rot *= np.sign(np.linalg.det(rot))
        pose = np.eye(4)
        pose[:3, :3], pose[:3, 3] = rot, centre + o * np.array([1.0, 0.7, -0.4])
        assert checker.collides(pose) == (checker.clearance(pose) < 0.003), k
    assert checker.collides(poses) == (naive < 0.003)
    behind = _poses(np.eye(3), np.array([[-0.5, 0.0, 0.0]]))  # behind the wall: negative
    assert checker.clearance(behind) < -0.4


def test_ring_on_peg(scene):
    cloud, obj, hang = scene
    s = OmniHangSettings()
    checker = CloudClearance(cloud, obj, s.clearance_m)
    assert checker.collides(hang), "the ring touches the peg at the hang (premise)"
    plan = plan_omnihang(cloud, hang, obj, T, s, seed=0)
    assert plan.solved
    assert plan.positions.shape == (T, 3) and plan.positions.dtype == np.float64
    assert np.array_equal(plan.positions[0], plan.goal)
    assert np.array_equal(plan.positions[-1], hang[:3, 3] + s.start_offset_m)
    # the release is the hang lifted straight up by the least clear multiple of lift_step_m
    lift = plan.goal[2] - hang[2, 3]
    assert np.array_equal(plan.goal[:2], hang[:2, 3])
    assert 0 < lift <= s.max_lift_m
    assert lift / s.lift_step_m == pytest.approx(round(lift / s.lift_step_m), abs=1e-9)
    assert not checker.collides(_poses(R_MINUS_X, plan.goal[None]))
    assert checker.collides(_poses(R_MINUS_X, plan.goal[None] - [0, 0, s.lift_step_m]))
    # the ring released there is threaded on the peg: the peg's axis passes through the hole
    centre = plan.goal - [0, 0, RING_R - TUBE_R]
    assert np.linalg.norm(centre[1:]) < RING_R - TUBE_R - PEG_R
    assert 0 < plan.goal[0] < PEG_LEN
    # the last stretch is the straight lead-in along the hanging x axis (here −x)
    arc = arc_length(plan.positions)
    inside = arc <= s.lead_in_m
    assert inside.sum() >= 2
    expected = plan.goal - arc[inside, None] * R_MINUS_X[:, 0]
    assert np.allclose(plan.positions[inside], expected, atol=1e-12)
    # collision-free as a dense re-interpolation, to the documented bound
    clear = dense_clearance(cloud, obj, plan.positions)
    assert clear >= guaranteed(plan.positions, s)
    assert plan.clearance_m == pytest.approx(clear, abs=5e-4)
    assert plan.n_checks > 0 and plan.seconds > 0


def test_obstacle_forces_detour(detour_scene):
    cloud, obj, hang = detour_scene
    s = OmniHangSettings()
    start = hang[:3, 3] + s.start_offset_m
    plan = plan_omnihang(cloud, hang, obj, T, s, seed=0)
    straight = np.stack([start, plan.goal - s.lead_in_m * hang[:3, 0], plan.goal])
    assert CloudClearance(cloud, obj).collides(
        _poses(R_MINUS_X, _densify(straight, 0.001))), "premise: the screen blocks the line"
    assert plan.solved
    assert arc_length(plan.positions)[-1] > arc_length(straight)[-1] + 0.02
    assert dense_clearance(cloud, obj, plan.positions) >= guaranteed(plan.positions, s)
    # and it really goes around the screen (beyond its edge in y or z)
    at_screen = plan.positions[np.argmin(np.abs(plan.positions[:, 0] - 0.11))]
    assert abs(at_screen[1]) > 0.045 or at_screen[2] > 0.085 or at_screen[2] < -0.025


def test_deterministic_per_seed(detour_scene):
    cloud, obj, hang = detour_scene
    s = OmniHangSettings()
    a = plan_omnihang(cloud, hang, obj, T, s, seed=3).positions
    other = plan_omnihang(cloud, hang, obj, T, s, seed=4).positions
    b = plan_omnihang(cloud, hang, obj, T, OmniHangSettings(max_checks=10**6), seed=3).positions
    assert np.array_equal(a, b), "same seed, other calls in between, other check budget"
    assert not np.array_equal(a, other), "the seed reaches the planner"


def test_unsolvable_returns_straight_fallback(scene):
    _, obj, _ = scene
    hang = hang_pose(x=0.1)
    # the ring at the hang sits inside a closed shell of points it cannot pass
    cloud = sphere_points(hang[:3, 3] - [0, 0, RING_R - TUBE_R], 0.05)
    s = OmniHangSettings(max_checks=3000)
    plan = plan_omnihang(cloud, hang, obj, T, s, seed=0)
    assert not plan.solved
    assert plan.seconds < 5.0
    assert plan.positions.shape == (T, 3)
    start, goal = hang[:3, 3] + s.start_offset_m, plan.goal
    lead = goal - s.lead_in_m * hang[:3, 0]
    assert np.array_equal(plan.positions[0], goal) and np.array_equal(plan.positions[-1], start)
    # every waypoint lies on the polyline start → lead → goal
    ab, bc = plan.positions[-1:0:-1], plan.positions
    on_first = np.linalg.norm(np.cross(ab - start, lead - start), axis=1) < 1e-12
    on_last = np.linalg.norm(np.cross(bc - lead, goal - lead), axis=1) < 1e-12
    assert (on_first[::-1] | on_last[1:]).all()
    # resampling may cut the corner at the lead-in point, never more
    length = arc_length(plan.positions)[-1]
    assert np.linalg.norm(goal - start) <= length <= np.linalg.norm(lead - start) + s.lead_in_m


def test_the_check_budget_stops_the_search(scene):
    """RRT-Connect stops when it has spent ``max_checks`` collision checks — a count, so the
    same on every machine — not earlier and not much later (an iteration's checks overshoot)."""
    _, obj, _ = scene
    hang = hang_pose(x=0.1)
    cloud = sphere_points(hang[:3, 3] - [0, 0, RING_R - TUBE_R], 0.05)  # no way out
    spent = {}
    for budget in (2000, 6000):
        s = OmniHangSettings(max_checks=budget)
        a, b = (plan_omnihang(cloud, hang, obj, T, s, seed=1) for _ in range(2))
        assert not a.solved and a.n_checks == b.n_checks, "the stop is deterministic"
        spent[budget] = a.n_checks
    rrt = spent[6000] - spent[2000]  # the checks before and after the search cancel
    assert 4000 <= rrt <= 4000 + 200, spent


def test_invalid_start_is_unsolved_not_an_error(scene):
    cloud, obj, hang = scene
    s = OmniHangSettings(start_offset_m=(0.03, 0.0, 0.0))  # the ring's start is on the peg
    plan = plan_omnihang(cloud, hang, obj, T, s, seed=0)
    assert not plan.solved and plan.positions.shape == (T, 3)


@pytest.mark.parametrize("kwargs, name", [
    (dict(cloud=np.zeros((20, 2))), "cloud"),
    (dict(cloud=np.zeros((5, 3))), "cloud"),
    (dict(cloud=np.full((20, 3), np.nan)), "cloud"),
    (dict(hang=np.eye(3)), "hang"),
    (dict(hang=np.diag([2.0, 1.0, 1.0, 1.0])), "hang"),
    (dict(hang=np.diag([-1.0, 1.0, 1.0, 1.0])), "hang"),
    (dict(object_points=np.zeros((0, 3))), "object_points"),
    (dict(T=1), "T"),
    (dict(seed=-1), "seed"),
])
def test_bad_input_names_the_argument(scene, kwargs, name):
    cloud, obj, hang = scene
    args = dict(cloud=cloud, hang=hang, object_points=obj, T=T) | kwargs
    with pytest.raises(ValueError, match=rf"^{name}:"):
        plan_omnihang(**args)
