"""The depth-camera model (``skt_lib/perception/sensor.py``): each effect does what its
docstring says, measured on scenes whose answer is known — a wall seen head-on or skimmed, a
thin rod in front of it, a plate-and-arm hook seen at an angle — with every other effect off,
pixel by pixel where the effect is a per-pixel rule."""

from dataclasses import replace

import numpy as np
import open3d as o3d
import pytest
from scipy.spatial.transform import Rotation

from skt_lib.geometry.convex import box, union
from skt_lib.geometry.se3 import transform_points
from skt_lib.perception.render import Camera, viewpoints
from skt_lib.perception.sensor import (SUPPORT_ID, WALL_ID, CameraScene, Intrinsics, SensorModel,
                                       _long_runs, camera_view, pose_error, sense)

K = Intrinsics(160, 120, 40.0)
#: Every effect off: a perfect sensor, the reference the effects are switched on against.
OFF = SensorModel().at(0)
#: A plate on the wall (x ∈ [0, 1 cm]) and an arm reaching 6 cm out of it at z = 0.
PLATE_ARM = union([box([0.005, 0.0, 0.0], [0.005, 0.02, 0.025]),
                   box([0.04, 0.0, 0.0], [0.03, 0.004, 0.004])])


def _head_on(distance: float = 0.4) -> np.ndarray:
    """A camera ``distance`` in front of the wall, looking straight at it (support frame)."""
    return Camera(np.array([distance, 0.0, 0.0]), np.zeros(3)).pose()


def _skimming(angle_deg: float = 80.0) -> np.ndarray:
    """A camera 40 cm from the origin whose optical axis meets the wall ``angle_deg`` off its
    normal: its rays meet the wall from about ``angle_deg`` − 26° to past 90°."""
    a = np.radians(angle_deg)
    return Camera(0.4 * np.array([np.cos(a), np.sin(a), 0.0]), np.zeros(3)).pose()


def _rod(width: float) -> CameraScene:
    """A vertical rod ``width`` wide standing 5 cm off the wall, on the optical axis."""
    return CameraScene(box([0.05, 0.0, 0.0], [0.005, width / 2, 0.05]))


def _bare_wall() -> CameraScene:
    """The wall alone (the support is a 2 mm speck 3 m to the side, out of every view)."""
    return CameraScene(box([0.0, 3.0, 0.0], [0.001, 0.001, 0.001]))


def _oblique_cameras(n: int = 4) -> list[np.ndarray]:
    """``n`` cameras 35 cm from ``PLATE_ARM``, left, right, above and below its arm."""
    cams = viewpoints(np.array([0.035, 0.0, 0.0]), 0.35, (-50.0, 50.0), (-20.0, 45.0), 2, 2)
    return [c.pose() for c in cams[:n]]


def _support_frame(points: np.ndarray, pose: np.ndarray) -> np.ndarray:
    return transform_points(pose, points)


def _pixels(points: np.ndarray, k: Intrinsics) -> np.ndarray:
    """``(H, W)`` bool: the pixels the camera-frame returns ``points`` came from."""
    col = np.round(points[:, 0] / points[:, 2] * k.focal_px + k.width / 2 - 0.5).astype(int)
    row = np.round(points[:, 1] / points[:, 2] * k.focal_px + k.height / 2 - 0.5).astype(int)
    mask = np.zeros((k.height, k.width), bool)
    mask[row, col] = True
    assert mask.sum() == len(points)  # one return per pixel
    return mask


def _neighbours(z: np.ndarray) -> np.ndarray:
    """``(4, H, W)``: the depth right, left, below and above every pixel (inf off the image)."""
    pad = np.pad(z, 1, constant_values=np.inf)
    return np.stack([pad[1:-1, 2:], pad[1:-1, :-2], pad[2:, 1:-1], pad[:-2, 1:-1]])


def _edges(z: np.ndarray, jump: float) -> np.ndarray:
    """``(H, W)`` bool: returns with a returning 4-neighbour more than ``jump`` off in depth."""
    nb = _neighbours(z)
    return np.isfinite(z) & (np.isfinite(nb) & (np.abs(nb - z) > jump)).any(0)


def _distance_to(mesh, points: np.ndarray) -> np.ndarray:
    scene = o3d.t.geometry.RaycastingScene()
    scene.add_triangles(o3d.core.Tensor(mesh.vertices.astype(np.float32)),
                        o3d.core.Tensor(mesh.faces.astype(np.uint32)))
    return scene.compute_distance(o3d.core.Tensor(points.astype(np.float32))).numpy()


def test_a_perfect_sensor_returns_the_surfaces_exactly_labelled():
    pose = _head_on()
    pts, labels = sense(_rod(0.01).depth(pose, K), K, OFF, np.random.default_rng(0))
    s = _support_frame(pts, pose)
    assert len(pts) == K.width * K.height  # the wall fills the view: every pixel returns
    np.testing.assert_allclose(s[labels == WALL_ID, 0], 0.0, atol=1e-6)
    rod = s[labels == SUPPORT_ID]
    assert len(rod) > 100
    np.testing.assert_allclose(rod[:, 0], 0.055, atol=1e-6)  # the rod's front face
    assert np.abs(rod[:, 1]).max() <= 0.005 + 1e-6


@pytest.mark.parametrize("view", range(4))
def test_a_perfect_sensor_puts_every_return_on_the_surface_it_is_labelled_with(view):
    pose = _oblique_cameras()[view]
    img = CameraScene(PLATE_ARM).depth(pose, K)
    pts, labels = sense(img, K, OFF, np.random.default_rng(0))
    assert len(pts) == np.isfinite(img.depth).sum()  # nothing lost
    np.testing.assert_array_equal(pts, K.directions()[np.isfinite(img.depth)]
                                  * img.depth[np.isfinite(img.depth)][:, None])
    s = _support_frame(pts, pose)
    hook, wall = s[labels == SUPPORT_ID], s[labels == WALL_ID]
    assert len(hook) > 300 and len(wall) > 10 * len(hook)
    assert _distance_to(PLATE_ARM, hook).max() < 1e-5
    assert np.abs(wall[:, 0]).max() < 1e-5
    assert (hook[:, 0] > 0.05).sum() > 20  # the arm's far end is seen, not only the plate
    # the wall is not returned where the plate hides it
    hidden = (np.abs(wall[:, 1]) < 0.019) & (np.abs(wall[:, 2]) < 0.024)
    assert not hidden.any()


@pytest.mark.parametrize("distance", [0.3, 0.6])
def test_depth_noise_grows_with_range_as_the_model_says(distance):
    noise_only = replace(OFF, sigma_a_m=SensorModel().sigma_a_m,
                         sigma_b_per_m=SensorModel().sigma_b_per_m)
    pose = _head_on(distance)
    pts, _ = sense(_bare_wall().depth(pose, K), K, noise_only, np.random.default_rng(1))
    depth_error = _support_frame(pts, pose)[:, 0]  # head-on: x error = depth error
    assert len(depth_error) == K.width * K.height
    expected = noise_only.sigma_a_m + noise_only.sigma_b_per_m * distance ** 2
    assert np.std(depth_error) == pytest.approx(expected, rel=0.05)
    assert abs(np.mean(depth_error)) < 0.05 * expected
    # each return moves along its own ray: the noise-free cloud, scaled per point
    clean, _ = sense(_bare_wall().depth(pose, K), K, OFF, np.random.default_rng(1))
    np.testing.assert_allclose(np.cross(pts, clean), 0.0, atol=1e-12)


def test_depth_is_quantized_to_the_step():
    quantized = replace(OFF, sigma_a_m=0.001, quant_m=0.001)
    pts, _ = sense(_rod(0.01).depth(_head_on(), K), K, quantized, np.random.default_rng(2))
    steps = pts[:, 2] / 0.001
    np.testing.assert_allclose(steps, np.round(steps), atol=1e-9)


def test_quantization_rounds_to_the_nearest_step():
    """A wall seen at an angle: depths vary smoothly over the image, each is rounded to the
    nearest step and moved no further."""
    img = _bare_wall().depth(_skimming(40.0), K)
    for step in (0.001, 0.004):
        pts, _ = sense(img, K, replace(OFF, quant_m=step), np.random.default_rng(2))
        true = img.depth[np.isfinite(img.depth)]
        np.testing.assert_allclose(pts[:, 2] / step, np.round(pts[:, 2] / step), atol=1e-9)
        assert np.abs(pts[:, 2] - true).max() <= step / 2 + 1e-12
        assert np.abs(pts[:, 2] - true).mean() == pytest.approx(step / 4, rel=0.1)  # uniform


def test_returns_are_lost_past_the_grazing_angle_and_kept_before_it():
    lo, hi = SensorModel().grazing_deg
    grazing = replace(OFF, grazing_deg=(lo, hi))
    head_on = sense(_bare_wall().depth(_head_on(), K), K, grazing, np.random.default_rng(3))[0]
    assert len(head_on) == K.width * K.height  # 0–26° off the normal: nothing lost
    img = _bare_wall().depth(_skimming(), K)
    seen = np.isfinite(img.depth)
    angle = np.degrees(np.arccos(np.clip(img.cos_incidence, 0.0, 1.0)))
    below, beyond = seen & (angle < lo), seen & (angle > hi)
    between = seen & ~below & ~beyond
    assert min(below.sum(), beyond.sum(), between.sum()) > 1000
    kept = _pixels(sense(img, K, grazing, np.random.default_rng(3))[0], K)
    assert kept[below].all()  # every return under grazing_deg[0] is kept
    assert not kept[beyond].any()  # and none past grazing_deg[1]
    # in between, a return is lost with a probability rising linearly from 0 to 1
    p_keep = 1 - (angle[between] - lo) / (hi - lo)
    sd = np.sqrt((p_keep * (1 - p_keep)).sum())
    assert kept[between].sum() == pytest.approx(p_keep.sum(), abs=4 * sd)
    near = between & (angle < (lo + hi) / 2)
    assert kept[near].mean() > kept[between & ~near].mean() + 0.3


def test_a_part_narrower_than_the_matching_window_vanishes():
    pose = _head_on(0.35)
    footprint = 0.3 / K.focal_px  # one pixel at the rod's front face (30 cm away), metres
    img = _rod(1.5 * footprint).depth(pose, K)
    widths = (img.label == SUPPORT_ID).sum(axis=1)
    assert set(widths[widths > 0]) <= {1, 2} and (widths > 0).sum() > 20  # 1–2 pixels wide
    for min_run, expect in ((1, (img.label == SUPPORT_ID).sum()), (3, 0)):
        _, labels = sense(img, K, replace(OFF, min_run_px=min_run), np.random.default_rng(4))
        assert (labels == SUPPORT_ID).sum() == expect
        assert (labels == WALL_ID).sum() == (img.label == WALL_ID).sum()  # wide wall runs stay
    wide = _rod(20 * footprint).depth(pose, K)
    _, labels = sense(wide, K, replace(OFF, min_run_px=3), np.random.default_rng(4))
    assert (labels == SUPPORT_ID).sum() == (wide.label == SUPPORT_ID).sum()  # wide parts stay


def test_flying_pixels_lie_between_the_two_surfaces_at_edges_only():
    pose = _head_on()
    img = _rod(0.01).depth(pose, K)
    edges = _edges(img.depth, OFF.edge_jump_m)
    assert 150 < edges.sum() < 400  # the rod's outline, on both sides of it
    clean, _ = sense(img, K, OFF, np.random.default_rng(5))
    nb = _neighbours(img.depth)
    nb_lo = np.where(np.isfinite(nb), nb, np.inf).min(0)[np.isfinite(img.depth)]
    nb_hi = np.where(np.isfinite(nb), nb, -np.inf).max(0)[np.isfinite(img.depth)]
    for rate in (0.3, 1.0):
        flying, labels = sense(img, K, replace(OFF, flying_rate=rate), np.random.default_rng(5))
        moved = flying[:, 2] != clean[:, 2]
        assert not moved[~edges[np.isfinite(img.depth)]].any()  # at depth edges only
        z = flying[moved, 2]
        assert ((z > np.minimum(clean[moved, 2], nb_lo[moved]))
                & (z < np.maximum(clean[moved, 2], nb_hi[moved]))).all()
        x = _support_frame(flying[moved], pose)[:, 0]
        assert ((x > 0.0) & (x < 0.055)).all()  # between the wall and the rod's front
        np.testing.assert_allclose(np.cross(flying, clean), 0.0, atol=1e-12)  # along the ray
        if rate == 1.0:
            assert moved.sum() == edges.sum()


def test_the_share_of_flying_pixels_is_the_flying_rate():
    img = _rod(0.01).depth(_head_on(), K)
    edges = _edges(img.depth, OFF.edge_jump_m).sum()
    model = replace(OFF, flying_rate=SensorModel().flying_rate)
    clean, _ = sense(img, K, OFF, np.random.default_rng(0))
    moved = sum((sense(img, K, model, np.random.default_rng(seed))[0][:, 2] != clean[:, 2]).sum()
                for seed in range(40))
    expected = 40 * edges * model.flying_rate  # about 250: binomial sd about 16
    assert moved == pytest.approx(expected, rel=0.2)


def test_pose_error_has_the_stated_size():
    model = SensorModel()
    axes, shifts = [], []
    for seed in range(5):
        e = pose_error(model, np.random.default_rng(seed))
        rot = Rotation.from_matrix(e[:3, :3])
        assert np.linalg.norm(e[:3, 3]) == pytest.approx(model.pose_t_m)
        assert np.degrees(rot.magnitude()) == pytest.approx(model.pose_r_deg)
        np.testing.assert_array_equal(e[3], [0.0, 0.0, 0.0, 1.0])
        axes.append(rot.as_rotvec() / rot.magnitude())
        shifts.append(e[:3, 3] / model.pose_t_m)
    for v in (np.array(axes), np.array(shifts)):  # random directions, not one fixed one
        assert np.linalg.norm(v - v[0], axis=1)[1:].min() > 0.1
    big = replace(model, pose_t_m=0.05, pose_r_deg=7.0)
    e = pose_error(big, np.random.default_rng(0))
    assert np.linalg.norm(e[:3, 3]) == pytest.approx(0.05)
    assert np.degrees(Rotation.from_matrix(e[:3, :3]).magnitude()) == pytest.approx(7.0)
    view = camera_view(_rod(0.01), _head_on(), K, model, np.random.default_rng(0))
    d = np.linalg.inv(view.pose) @ view.assumed
    assert np.linalg.norm(d[:3, 3]) == pytest.approx(model.pose_t_m)
    angle = np.degrees(Rotation.from_matrix(d[:3, :3]).magnitude())
    assert angle == pytest.approx(model.pose_r_deg)
    np.testing.assert_array_equal(view.pose, _head_on())  # the truth is left as it was


def test_severity_scales_every_effect_and_zero_is_perfect():
    base = SensorModel()
    assert base.at(1) == base
    two = base.at(2)
    assert (two.sigma_a_m, two.sigma_b_per_m, two.flying_rate, two.pose_t_m, two.pose_r_deg) == \
        pytest.approx((2 * base.sigma_a_m, 2 * base.sigma_b_per_m, 2 * base.flying_rate,
                       2 * base.pose_t_m, 2 * base.pose_r_deg))
    models = [base.at(s) for s in (0, 0.5, 1, 2, 3, 4)]
    for lo, hi in zip(models, models[1:]):  # every effect grows (or stays) with severity
        assert hi.sigma_a_m > lo.sigma_a_m and hi.sigma_b_per_m > lo.sigma_b_per_m
        assert hi.flying_rate > lo.flying_rate and hi.pose_t_m > lo.pose_t_m
        assert hi.pose_r_deg > lo.pose_r_deg and hi.min_run_px >= lo.min_run_px
        assert hi.grazing_deg[0] <= lo.grazing_deg[0] and hi.grazing_deg[1] <= lo.grazing_deg[1]
        assert hi.quant_m >= lo.quant_m
    worst = base.at(4)
    assert worst.min_run_px > base.min_run_px and worst.grazing_deg[1] < base.grazing_deg[1]
    with pytest.raises(ValueError, match="severity"):
        base.at(-1)
    # severity 0: the exact ray cast, whatever the generator, and no pose error
    img = CameraScene(PLATE_ARM).depth(_oblique_cameras()[0], K)
    exact = K.directions()[np.isfinite(img.depth)] * img.depth[np.isfinite(img.depth)][:, None]
    for seed in (6, 7):
        pts, labels = sense(img, K, base.at(0), np.random.default_rng(seed))
        np.testing.assert_array_equal(pts, exact)
        np.testing.assert_array_equal(labels, img.label[np.isfinite(img.depth)])
    np.testing.assert_array_equal(pose_error(base.at(0), np.random.default_rng(6)), np.eye(4))


def test_same_generator_same_cloud():
    scene, pose, model = CameraScene(PLATE_ARM), _oblique_cameras()[1], SensorModel()
    a = camera_view(scene, pose, K, model, np.random.default_rng(8))
    b = camera_view(scene, pose, K, model, np.random.default_rng(8))
    np.testing.assert_array_equal(a.points, b.points)
    np.testing.assert_array_equal(a.labels, b.labels)
    np.testing.assert_array_equal(a.assumed, b.assumed)
    c = camera_view(scene, pose, K, model, np.random.default_rng(9))
    assert len(c.points) != len(a.points) or not np.array_equal(c.points, a.points)
    assert not np.array_equal(c.assumed, a.assumed)


def test_runs_of_one_surface_shorter_than_the_window_are_dropped_exactly():
    inf = np.inf
    z = np.array([[inf, 1.0, 1.0, 1.0, 2.0, 2.0, 1.0, 1.0, 1.0, 1.0]])  # runs: 3, 2, 4
    keep = _long_runs(z, jump=0.005, min_run=3)
    np.testing.assert_array_equal(keep[0], [False, True, True, True, False, False, True, True,
                                            True, True])
    np.testing.assert_array_equal(_long_runs(z, 0.005, 1)[0], np.isfinite(z[0]))
    # runs do not carry over from one row to the next
    two_rows = np.array([[inf, inf, 1.0, 1.0], [1.0, 1.0, inf, inf]])
    assert not _long_runs(two_rows, 0.005, 3).any()
