import numpy as np
import pytest

from skt_lib.errors import DataError
from skt_lib.geometry.convex import box
from skt_lib.io import read_npz, write_npz_atomic
from skt_lib.perception.pointcloud import (
    add_depth_noise, check_cloud, farthest_point_sample, farthest_point_sample_naive,
)
from skt_lib.perception.render import DepthRenderer, viewpoints


@pytest.mark.parametrize("n_points,n", [(50, 10), (3000, 1000), (1200, 1200)])
def test_fps_matches_naive_reference(n_points, n):
    pts = np.random.default_rng(n_points).normal(size=(n_points, 3))
    fast = farthest_point_sample(pts, n)
    assert np.array_equal(fast, np.sort(farthest_point_sample_naive(pts, n)))
    assert len(np.unique(fast)) == n


def test_cloud_checks_name_the_problem():
    with pytest.raises(ValueError, match="empty"):
        check_cloud(np.zeros((0, 3)))
    with pytest.raises(ValueError, match="NaN"):
        check_cloud(np.array([[0.0, np.nan, 0.0]]))
    with pytest.raises(ValueError, match=r"\(N, 3\)"):
        check_cloud(np.zeros((4, 2)), "cloud")
    with pytest.raises(ValueError, match="n: need"):
        farthest_point_sample(np.zeros((3, 3)), 5)


def test_viewpoints_look_at_the_target_from_the_front():
    cams = viewpoints(np.array([0.05, 0, 0]), 0.35, (-60, 60), (-20, 55), 7, 6)
    assert len(cams) == 42
    for c in cams:
        t = c.pose()
        r = t[:3, :3]
        assert r.T @ r == pytest.approx(np.eye(3), abs=1e-12) and np.linalg.det(r) == pytest.approx(1)
        forward = r[:, 2]
        assert forward == pytest.approx((c.target - c.eye) / 0.35)
        assert c.eye[0] > c.target[0]  # in front of the wall side
        assert np.linalg.norm(c.eye - c.target) == pytest.approx(0.35)


def test_rendered_points_lie_on_the_visible_surface():
    mesh = box([0.05, 0.0, 0.0], [0.02, 0.03, 0.01])
    r = DepthRenderer(mesh, 40.0)
    cam = viewpoints(np.array([0.05, 0, 0]), 0.3, (0, 0), (0, 0), 1, 1)[0]  # straight in front
    pts, rays = r.points(cam, 160, 120)
    assert len(pts) > 500
    assert np.abs(r.distance(pts)).max() < 1e-5
    assert pts[:, 0] == pytest.approx(0.07, abs=1e-5)  # only the front face is seen
    noisy = add_depth_noise(pts, rays, 0.001, np.random.default_rng(0))
    along = ((noisy - pts) * rays).sum(1)
    assert np.allclose(np.linalg.norm(noisy - pts, axis=1), np.abs(along)) and along.std() > 5e-4


def test_npz_is_byte_stable_and_checked(tmp_path):
    arrays = {"points": np.ones((2, 4, 3), np.float32), "n": np.arange(2, dtype=np.int32)}
    write_npz_atomic(tmp_path / "a.npz", arrays)
    write_npz_atomic(tmp_path / "b.npz", arrays)
    assert (tmp_path / "a.npz").read_bytes() == (tmp_path / "b.npz").read_bytes()
    spec = {"points": ("float32", 3), "n": ("int32", 1)}
    assert read_npz(tmp_path / "a.npz", spec)["points"].shape == (2, 4, 3)
    with pytest.raises(DataError, match="'points' is float32 with 3 dims, expected float64"):
        read_npz(tmp_path / "a.npz", {"points": ("float64", 3)})
    write_npz_atomic(tmp_path / "nan.npz", {"points": np.full((1, 1, 3), np.nan, np.float32)})
    with pytest.raises(DataError, match="NaN"):
        read_npz(tmp_path / "nan.npz", {"points": ("float32", 3)})
    (tmp_path / "bad.npz").write_bytes(b"not a zip")
    with pytest.raises(DataError, match="not a readable"):
        read_npz(tmp_path / "bad.npz", spec)
    with pytest.raises(DataError, match="dtype object"):
        write_npz_atomic(tmp_path / "o.npz", {"x": np.array([{}], dtype=object)})
