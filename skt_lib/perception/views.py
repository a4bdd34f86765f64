"""Render one support's partial clouds: ``V`` views × ``N`` points, written as one NPZ.

A view with fewer than ``N`` hit pixels is rendered again at twice the resolution; if it is
still short, its points are padded with duplicates drawn by the view's generator and
``n_visible`` records how many are distinct. Each view's points are shuffled (FPS keeps
input order), so point order carries no information.
"""

import functools
import time
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from skt_lib.config.render_views import RenderViewsParams
from skt_lib.geometry.export import read_obj
from skt_lib.io import write_npz_atomic
from skt_lib.perception.pointcloud import add_depth_noise, sample_to
from skt_lib.perception.render import DepthRenderer, viewpoints
from skt_lib.seeding import item_rng

RENDER_SPEC = {"points": ("float32", 3), "cameras": ("float32", 3), "n_visible": ("int32", 1)}
#: Where ``render_views`` and ``affordance_maps`` keep the depth-camera views of the training
#: and validation supports (``render_views.sensor_views_severity`` > 0).
SENSOR_DIR = "sensor"


@dataclass(frozen=True)
class RenderTask:
    support_id: str
    mesh_path: str
    out_path: str
    seed: int
    params: RenderViewsParams


def support_cameras(mesh, p: RenderViewsParams) -> list:
    """The ``n_azimuth × n_elevation`` cameras of :func:`viewpoints` around ``mesh``'s box centre."""
    target = (mesh.vertices.min(0) + mesh.vertices.max(0)) / 2
    return viewpoints(target, p.distance_m, p.azimuth_deg, p.elevation_deg, p.n_azimuth, p.n_elevation)


def render_view(renderer: DepthRenderer, cam, p: RenderViewsParams, rng: np.random.Generator,
                name: str) -> tuple[np.ndarray, int, float, bool]:
    """One view: (points (N, 3) float64, support frame; distinct points seen, ≤ N; ray-casting
    seconds; whether it was rendered again at twice the resolution)."""
    t0 = time.perf_counter()
    pts, rays = renderer.points(cam, p.width, p.height)
    seconds = time.perf_counter() - t0
    rerendered = len(pts) < p.n_points
    if rerendered:
        pts, rays = renderer.points(cam, 2 * p.width, 2 * p.height)
    pts = add_depth_noise(pts, rays, p.noise_std_m, rng)
    if len(pts) == 0:
        raise ValueError(f"{name}: the support is not visible")
    return sample_to(pts, p.n_points, rng), min(len(pts), p.n_points), seconds, rerendered


def render_support(task: RenderTask, viewer: Callable | None = None) -> dict:
    """Render and write one support's views. ``viewer(mesh, params)`` makes the view function
    ``(camera, rng, name) -> (points, distinct points, seconds, flag)``; by default a perfect
    ray cast of the support alone (:func:`render_view`; the flag: rendered again at twice the
    resolution)."""
    p = task.params
    (mesh,) = read_obj(task.mesh_path)
    renderer = DepthRenderer(mesh, p.fov_deg)
    view = viewer(mesh, p) if viewer else functools.partial(render_view, renderer, p=p)
    cams = support_cameras(mesh, p)
    points = np.zeros((len(cams), p.n_points, 3), np.float32)
    n_visible = np.zeros(len(cams), np.int32)
    render_s, n_rerendered = [], 0
    for v, cam in enumerate(cams):
        rng = item_rng(task.seed, "render_views", f"{task.support_id}/{v}")
        points[v], n_visible[v], seconds, again = view(cam, rng=rng,
                                                       name=f"{task.support_id} view {v}")
        render_s.append(seconds)
        n_rerendered += again
    write_npz_atomic(task.out_path, {
        "points": points,
        "cameras": np.stack([c.pose() for c in cams]).astype(np.float32),
        "n_visible": n_visible,
    })
    on_surface = float((renderer.distance(points.reshape(-1, 3)) <= 1e-3).mean())
    return {"support_id": task.support_id, "render_s": render_s, "n_rerendered": n_rerendered,
            "n_padded": int((n_visible < p.n_points).sum()), "on_surface_rate": on_surface}
