"""``render_views`` with a depth camera (``render_views.sensor_severity`` > 0,
``skt_lib/perception/camera_views.py``)."""

import numpy as np

from tests.perception.test_wall_frame import PEG


def test_render_views_with_a_depth_camera_gives_support_frame_views(tmp_path):
    """``render_views.sensor_severity`` > 0: each view is what ``skt predict --camera`` makes
    of a camera's cloud — in the support frame, on the hook (not the wall), N points."""
    from skt_lib.config.params_file import load_params
    from skt_lib.geometry.export import obj_text
    from skt_lib.io import read_npz
    from skt_lib.perception.camera_views import camera_viewer
    from skt_lib.perception.render import DepthRenderer
    from skt_lib.perception.views import RENDER_SPEC, RenderTask, render_support

    p = load_params("params.yaml").render_views.model_copy(
        update={"n_azimuth": 3, "n_elevation": 2, "sensor_severity": 1.0})
    (tmp_path / "peg.obj").write_text(obj_text(PEG, "peg"))
    task = RenderTask("peg", str(tmp_path / "peg.obj"), str(tmp_path / "peg.npz"), 7, p)
    out = render_support(task, viewer=camera_viewer)
    views = read_npz(tmp_path / "peg.npz", RENDER_SPEC)["points"]
    assert views.shape == (6, p.n_points, 3) and out["n_rerendered"] == 0  # no frame fell back
    d = DepthRenderer(PEG, p.fov_deg).distance(views.reshape(-1, 3).astype(np.float64))
    assert np.median(d) < 0.0015 and (d > 0.006).mean() < 0.01  # on the hook, sensor noise aside
    again = render_support(RenderTask("peg", task.mesh_path, str(tmp_path / "again.npz"), 7, p),
                           viewer=camera_viewer)
    np.testing.assert_array_equal(read_npz(tmp_path / "again.npz", RENDER_SPEC)["points"], views)
    assert again["on_surface_rate"] == out["on_surface_rate"]
