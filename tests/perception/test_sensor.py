"""The depth-camera model (``skt_lib/perception/sensor.py``): each effect does what its
docstring says, measured on scenes whose answer is known — a wall seen head-on, a thin rod
in front of it — and nothing else changes the returns."""

from dataclasses import replace

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from skt_lib.geometry.convex import box
from skt_lib.geometry.se3 import transform_points
from skt_lib.perception.render import Camera
from skt_lib.perception.sensor import (SUPPORT_ID, WALL_ID, CameraScene, Intrinsics, SensorModel,
                                       _long_runs, camera_view, pose_error, sense)

K = Intrinsics(160, 120, 40.0)
#: Every effect off: a perfect sensor, the reference the effects are switched on against.
OFF = SensorModel().at(0)


def _head_on(distance: float = 0.4) -> np.ndarray:
    """A camera ``distance`` in front of the wall, looking straight at it (support frame)."""
    return Camera(np.array([distance, 0.0, 0.0]), np.zeros(3)).pose()


def _rod(width: float) -> CameraScene:
    """A vertical rod ``width`` wide standing 5 cm off the wall, on the optical axis."""
    return CameraScene(box([0.05, 0.0, 0.0], [0.005, width / 2, 0.05]))


def _support_frame(points: np.ndarray, pose: np.ndarray) -> np.ndarray:
    return transform_points(pose, points)


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


def test_depth_noise_grows_with_range_as_the_model_says():
    noise_only = replace(OFF, sigma_a_m=0.0005, sigma_b_per_m=0.0025)
    scene = CameraScene(box([0.0, 3.0, 0.0], [0.001, 0.001, 0.001]))  # a speck out of view
    for distance in (0.3, 0.6):
        pose = _head_on(distance)
        pts, _ = sense(scene.depth(pose, K), K, noise_only, np.random.default_rng(1))
        depth_error = _support_frame(pts, pose)[:, 0]  # head-on: x error = depth error
        expected = 0.0005 + 0.0025 * distance ** 2
        assert np.std(depth_error) == pytest.approx(expected, rel=0.05)
        assert abs(np.mean(depth_error)) < 0.1 * expected


def test_depth_is_quantized_to_the_step():
    quantized = replace(OFF, sigma_a_m=0.001, quant_m=0.001)
    pts, _ = sense(_rod(0.01).depth(_head_on(), K), K, quantized, np.random.default_rng(2))
    steps = pts[:, 2] / 0.001
    np.testing.assert_allclose(steps, np.round(steps), atol=1e-9)


def test_returns_are_lost_past_the_grazing_angle_and_kept_before_it():
    grazing = replace(OFF, grazing_deg=(60.0, 75.0))
    scene = CameraScene(box([0.0, 3.0, 0.0], [0.001, 0.001, 0.001]))
    head_on = sense(scene.depth(_head_on(), K), K, grazing, np.random.default_rng(3))[0]
    assert len(head_on) == K.width * K.height  # 0–11° off the normal: nothing lost
    # a camera skimming the wall: its rays meet it from under 60° to over 85° off the normal
    eye = np.array([0.4 * np.cos(np.radians(80)), 0.4 * np.sin(np.radians(80)), 0.0])
    img = scene.depth(Camera(eye, np.zeros(3)).pose(), K)
    seen = np.isfinite(img.depth)
    angle = np.degrees(np.arccos(img.cos_incidence[seen]))
    assert (angle > 75).sum() > 1000 and (angle < 60).sum() > 1000
    kept = len(sense(img, K, grazing, np.random.default_rng(3))[0])
    assert kept <= (angle < 75).sum()  # nothing past 75° is kept
    assert kept >= 0.9 * (angle < 60).sum()  # and what is under 60° is


def test_a_part_narrower_than_the_matching_window_vanishes():
    pose = _head_on(0.35)
    footprint = 0.35 / K.focal_px  # one pixel at the rod's depth, metres
    img = _rod(1.5 * footprint).depth(pose, K)  # 1–2 pixels wide in the image
    for min_run, expect_rod in ((1, True), (3, False)):
        _, labels = sense(img, K, replace(OFF, min_run_px=min_run), np.random.default_rng(4))
        assert ((labels == SUPPORT_ID).sum() > 0) == expect_rod
    wide = _rod(20 * footprint).depth(pose, K)
    _, labels = sense(wide, K, replace(OFF, min_run_px=3), np.random.default_rng(4))
    assert (labels == SUPPORT_ID).sum() == (wide.label == SUPPORT_ID).sum()  # wide parts stay


def test_flying_pixels_lie_between_the_two_surfaces_at_edges_only():
    pose = _head_on()
    img = _rod(0.01).depth(pose, K)
    clean, _ = sense(img, K, OFF, np.random.default_rng(5))
    for rate in (0.3, 1.0):
        flying, labels = sense(img, K, replace(OFF, flying_rate=rate), np.random.default_rng(5))
        x = _support_frame(flying, pose)[:, 0]
        moved = ~np.isclose(x, _support_frame(clean, pose)[:, 0], atol=1e-9)
        assert ((x[moved] > 0.0) & (x[moved] < 0.055)).all()  # between wall and rod front
        # the rod's two vertical edges, 2 px each side (rod and wall pixel): 4 columns × rows
        rod_rows = (img.label == SUPPORT_ID).any(axis=1).sum()
        edge_pixels = 4 * rod_rows
        assert moved.sum() == pytest.approx(rate * edge_pixels, rel=0.25)
        assert not moved[np.abs(_support_frame(clean, pose)[:, 1]) > 0.01].any()  # off the edges


def test_pose_error_has_the_stated_size():
    model = SensorModel()
    for seed in range(5):
        e = pose_error(model, np.random.default_rng(seed))
        assert np.linalg.norm(e[:3, 3]) == pytest.approx(model.pose_t_m)
        assert np.degrees(Rotation.from_matrix(e[:3, :3]).magnitude()) == pytest.approx(model.pose_r_deg)
    view = camera_view(_rod(0.01), _head_on(), K, model, np.random.default_rng(0))
    d = np.linalg.inv(view.pose) @ view.assumed
    assert np.linalg.norm(d[:3, 3]) == pytest.approx(model.pose_t_m)


def test_severity_scales_every_effect_and_zero_is_perfect():
    base = SensorModel()
    assert base.at(1) == base
    lo, hi = base.at(1), base.at(3)
    assert hi.sigma_a_m > lo.sigma_a_m and hi.sigma_b_per_m > lo.sigma_b_per_m
    assert hi.flying_rate > lo.flying_rate and hi.pose_t_m > lo.pose_t_m
    assert hi.min_run_px > lo.min_run_px and hi.grazing_deg[0] < lo.grazing_deg[0]
    with pytest.raises(ValueError, match="severity"):
        base.at(-1)
    pose = _head_on()
    img = _rod(0.01).depth(pose, K)
    a, _ = sense(img, K, base.at(0), np.random.default_rng(6))
    b, _ = sense(img, K, base.at(0), np.random.default_rng(7))
    np.testing.assert_array_equal(a, b)  # no randomness left at severity 0


def test_same_generator_same_cloud():
    scene, pose, model = _rod(0.01), _head_on(), SensorModel()
    a = camera_view(scene, pose, K, model, np.random.default_rng(8))
    b = camera_view(scene, pose, K, model, np.random.default_rng(8))
    np.testing.assert_array_equal(a.points, b.points)
    np.testing.assert_array_equal(a.assumed, b.assumed)


def test_runs_of_one_surface_shorter_than_the_window_are_dropped_exactly():
    inf = np.inf
    z = np.array([[inf, 1.0, 1.0, 1.0, 2.0, 2.0, 1.0, 1.0, 1.0, 1.0]])  # runs: 3, 2, 4
    keep = _long_runs(z, jump=0.005, min_run=3)
    np.testing.assert_array_equal(keep[0], [False, True, True, True, False, False, True, True,
                                            True, True])
    np.testing.assert_array_equal(_long_runs(z, 0.005, 1)[0], np.isfinite(z[0]))
