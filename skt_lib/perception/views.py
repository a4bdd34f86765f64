"""Render one support's partial clouds: ``V`` views × ``N`` points, written as one NPZ.

A view with fewer than ``N`` hit pixels is rendered again at twice the resolution; if it is
still short, its points are padded with duplicates drawn by the view's generator and
``n_visible`` records how many are distinct. Each view's points are shuffled (FPS keeps
input order), so point order carries no information.
"""

import time
from dataclasses import dataclass

import numpy as np

from skt_lib.config import RenderViewsParams
from skt_lib.geometry.export import read_obj
from skt_lib.io import write_npz_atomic
from skt_lib.perception.pointcloud import add_depth_noise, farthest_point_sample
from skt_lib.perception.render import DepthRenderer, viewpoints
from skt_lib.seeding import item_rng

RENDER_SPEC = {"points": ("float32", 3), "cameras": ("float32", 3), "n_visible": ("int32", 1)}


@dataclass(frozen=True)
class RenderTask:
    support_id: str
    mesh_path: str
    out_path: str
    seed: int
    params: RenderViewsParams


def render_support(task: RenderTask) -> dict:
    p = task.params
    (mesh,) = read_obj(task.mesh_path)
    renderer = DepthRenderer(mesh, p.fov_deg)
    target = (mesh.vertices.min(0) + mesh.vertices.max(0)) / 2
    cams = viewpoints(target, p.distance_m, p.azimuth_deg, p.elevation_deg, p.n_azimuth, p.n_elevation)
    points = np.zeros((len(cams), p.n_points, 3), np.float32)
    n_visible = np.zeros(len(cams), np.int32)
    render_s, n_rerendered = [], 0
    for v, cam in enumerate(cams):
        rng = item_rng(task.seed, "render_views", f"{task.support_id}/{v}")
        t0 = time.perf_counter()
        pts, rays = renderer.points(cam, p.width, p.height)
        render_s.append(time.perf_counter() - t0)
        if len(pts) < p.n_points:
            n_rerendered += 1
            pts, rays = renderer.points(cam, 2 * p.width, 2 * p.height)
        pts = add_depth_noise(pts, rays, p.noise_std_m, rng)
        n_visible[v] = min(len(pts), p.n_points)
        if len(pts) == 0:
            raise ValueError(f"{task.support_id} view {v}: the support is not visible")
        if len(pts) >= p.n_points:
            chosen = pts[farthest_point_sample(pts, p.n_points)]
        else:
            extra = rng.choice(len(pts), p.n_points - len(pts))
            chosen = np.vstack([pts, pts[extra]])
        points[v] = chosen[rng.permutation(p.n_points)]
    write_npz_atomic(task.out_path, {
        "points": points,
        "cameras": np.stack([c.pose() for c in cams]).astype(np.float32),
        "n_visible": n_visible,
    })
    on_surface = float((renderer.distance(points.reshape(-1, 3)) <= 1e-3).mean())
    return {"support_id": task.support_id, "render_s": render_s, "n_rerendered": n_rerendered,
            "n_padded": int((n_visible < p.n_points).sum()), "on_surface_rate": on_surface}
