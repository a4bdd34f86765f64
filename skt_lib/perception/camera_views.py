"""``render_views`` with a depth camera (``render_views.sensor_severity`` > 0): each view is
what ``skt predict --camera`` would make of a real camera's cloud.

The support and its wall are seen through the sensor model of
:mod:`skt_lib.perception.sensor` at that severity; the support frame is found from the wall
(:func:`skt_lib.perception.wall_frame.support_frame`, up = the true gravity in the camera
frame), the wall removed, and the rest cleaned (:func:`~skt_lib.perception.pointcloud.clean_cloud`)
and sampled to ``n_points`` — the path a user's cloud takes to the model. Where the frame
cannot be found (the wall or the hook too broken up at high severities) the view falls back
to the true camera pose with the wall cut at the true plane, and says so.
"""

import time
from collections.abc import Callable

import numpy as np

from skt_lib.config.render_views import RenderViewsParams
from skt_lib.errors import InputError
from skt_lib.geometry.convex import Mesh
from skt_lib.geometry.se3 import transform_points
from skt_lib.perception.pointcloud import clean_cloud, sample_to
from skt_lib.perception.sensor import CameraScene, Intrinsics, SensorModel, camera_view
from skt_lib.perception.wall_frame import WallSettings, support_frame


def camera_viewer(mesh: Mesh, p: RenderViewsParams) -> Callable:
    """A view function for :func:`skt_lib.perception.views.render_support`: ``(camera, rng,
    name) -> (points (N, 3) support frame, distinct points ≤ N, seconds, fell back to the
    true frame)``."""
    scene, k = CameraScene(mesh), Intrinsics(p.width, p.height, p.fov_deg)
    model = SensorModel().at(p.sensor_severity)

    def view(cam, rng: np.random.Generator, name: str) -> tuple[np.ndarray, int, float, bool]:
        t0 = time.perf_counter()
        pose = cam.pose()
        seen = camera_view(scene, pose, k, model, rng)
        seconds = time.perf_counter() - t0
        try:
            pts, fell_back = support_frame(seen.points, pose[:3, :3].T @ [0.0, 0.0, 1.0],
                                           name=name).points, False
        except InputError:
            pts = transform_points(pose, seen.points)
            pts, fell_back = pts[pts[:, 0] > WallSettings.off_wall_m], True
        try:
            pts = clean_cloud(pts, name=name).points
        except ValueError:
            pass  # too little for the cleaning: the view keeps what it has
        if len(pts) == 0:
            raise ValueError(f"{name}: the support is not visible")
        return sample_to(pts, p.n_points, rng), min(len(pts), p.n_points), seconds, fell_back

    return view
