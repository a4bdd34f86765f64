"""The support frame from a raw camera cloud (``skt_lib/perception/wall_frame.py``): on
views a depth camera gives of a hook on its wall, the frame lands within 5 mm and 2° of the
truth with up from gravity or from a level camera, the wall is gone from what is returned,
the origin follows the generated supports' convention, and bad clouds are refused naming
what is wrong."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from skt_lib.errors import InputError
from skt_lib.geometry.convex import union
from skt_lib.geometry.se3 import invert
from skt_lib.geometry.supports import Stroke, SupportShape
from skt_lib.perception.render import viewpoints
from skt_lib.perception.sensor import CameraScene, Intrinsics, SensorModel, camera_view
from skt_lib.perception.wall_frame import support_frame

K = Intrinsics(320, 240, 40.0)  # render_views' camera
UP = np.array([0.0, 0.0, 1.0])


def _mesh(*arms: np.ndarray):
    return union(SupportShape("test", tuple(Stroke(a, 0.004, False) for a in arms)).parts())


PEG = _mesh(np.array([[0.01, 0.0, 0.0], [0.04, 0.0, 0.01], [0.08, 0.0, 0.03]]))
#: a lower arm at the origin and an upper one 5 cm above: the plate spans both
DOUBLE = _mesh(np.array([[0.01, 0.0, 0.0], [0.07, 0.0, 0.0], [0.08, 0.0, 0.02]]),
               np.array([[0.01, 0.0, 0.05], [0.05, 0.0, 0.07]]))


def _cameras(mesh, n: int = 6) -> list[np.ndarray]:
    centre = (mesh.vertices.min(0) + mesh.vertices.max(0)) / 2
    cams = viewpoints(centre, 0.35, (-60.0, 60.0), (-20.0, 55.0), 7, 6)
    return [cams[i].pose() for i in np.linspace(0, len(cams) - 1, n).astype(int)]


def _error(est: np.ndarray, true: np.ndarray) -> tuple[float, float]:
    e = est @ invert(true)
    return 1000 * np.linalg.norm(e[:3, 3]), np.degrees(Rotation.from_matrix(e[:3, :3]).magnitude())


def _view(mesh, pose, seed=0):
    return camera_view(CameraScene(mesh), pose, K, SensorModel(), np.random.default_rng(seed))


@pytest.mark.parametrize("mesh", [PEG, DOUBLE], ids=["peg", "double_hook"])
def test_frame_within_5_mm_and_2_degrees_with_up_or_a_level_camera(mesh):
    for k, pose in enumerate(_cameras(mesh)):
        view = _view(mesh, pose, k)
        for up in (pose[:3, :3].T @ UP, None):  # gravity in the camera frame; level camera
            t_mm, r_deg = _error(support_frame(view.points, up).camera_to_support, pose)
            assert t_mm <= 5.0 and r_deg <= 2.0, (k, up, t_mm, r_deg)


def test_the_wall_is_removed_and_the_hook_kept():
    pose = _cameras(PEG)[2]
    view = _view(PEG, pose)
    wf = support_frame(view.points, pose[:3, :3].T @ UP)
    hook = (view.points @ pose[:3, :3].T + pose[:3, 3])[view.labels == 1]
    assert wf.n_wall > 10 * len(wf.points)  # most of the view was wall
    # nothing of the wall away from the hook: a few flying pixels at its edges at most
    d = np.linalg.norm(wf.points[:, None] - hook[None, ::2], axis=2).min(1)
    assert np.median(d) < 0.001 and (d > 0.01).mean() < 0.005
    assert (wf.points[:, 0] > 0.05).sum() > 50  # the arm's far part is there


def test_the_origin_is_the_lowest_arms_root_not_the_plates_centre():
    pose = _cameras(DOUBLE)[3]
    wf = support_frame(_view(DOUBLE, pose).points, pose[:3, :3].T @ UP)
    origin = (pose @ invert(wf.camera_to_support))[:3, 3]  # the estimate, true support frame
    np.testing.assert_allclose(origin, [0.0, 0.0, 0.0], atol=0.004)  # the plate's centre: z 0.025


def test_point_order_does_not_matter():
    pose = _cameras(PEG)[1]
    pts = _view(PEG, pose).points
    a = support_frame(pts, None)
    b = support_frame(pts[np.random.default_rng(3).permutation(len(pts))], None)
    np.testing.assert_array_equal(a.camera_to_support, b.camera_to_support)
    np.testing.assert_array_equal(a.points, b.points)


def _wall(n: int = 20000, distance: float = 0.4) -> np.ndarray:
    """A bare wall seen head-on from ``distance`` (camera frame: the wall at z = distance)."""
    rng = np.random.default_rng(5)
    return np.c_[rng.uniform(-0.15, 0.15, (n, 2)), distance + rng.normal(0, 0.001, n)]


@pytest.mark.parametrize("points, up, message", [
    (np.random.default_rng(1).normal(0, 0.05, (5000, 3)) + [0, 0, 0.4], None, "no wall plane"),
    (_wall(), None, "no structure stands off the wall plane"),
    (_wall(), np.array([0.0, 0.0, -1.0]), "from the wall's normal"),
    (_wall() * 1000, None, "a cloud in millimetres"),
    (_wall(50), None, "50 finite points"),
], ids=["no_plane", "bare_wall", "up_into_wall", "millimetres", "too_few"])
def test_bad_clouds_are_refused_naming_what_is_wrong(points, up, message):
    with pytest.raises(InputError, match=message) as err:
        support_frame(points, up, name="scan.ply")
    assert str(err.value).startswith("scan.ply") or str(err.value).startswith("--up")


def test_an_arm_seen_end_on_keeps_its_tip():
    """Looking straight down a peg, its sides are lost at grazing angles: its upturned tip
    is a cluster of its own, apart from the plate, and still part of the hook."""
    peg = _mesh(np.array([[0.01, 0.0, 0.0], [0.1, 0.0, 0.0], [0.1, 0.0, 0.04]]))
    pose = viewpoints(np.array([0.05, 0.0, 0.0]), 0.35, (0.0, 0.0), (0.0, 0.0), 1, 1)[0].pose()
    view = _view(peg, pose)
    tip = (view.points @ pose[:3, :3].T + pose[:3, 3])[view.labels == 1]
    assert ((tip[:, 0] > 0.03) & (tip[:, 0] < 0.09)).sum() < 0.05 * len(tip)  # sides lost
    wf = support_frame(view.points, pose[:3, :3].T @ UP)
    far = wf.points[wf.points[:, 0] > 0.095]  # (voxel-downsampled: fewer points than seen)
    assert len(far) > 30 and far[:, 2].max() > 0.035  # the whole riser, up to its top
