"""Depth rendering of a support (Open3D ``RaycastingScene``) from a ring of viewpoints.

Viewpoint layout (support frame): cameras on a sphere of radius ``distance_m`` around the
support's bounding-box centre, at ``n_azimuth`` azimuths evenly spanning ``azimuth_deg``
(0° = straight in front, +x; positive toward +y) and ``n_elevation`` elevations evenly
spanning ``elevation_deg`` (positive = above), all looking at that centre with +z up: the
hemisphere in front of the wall from which a robot sees the item. Camera poses are
camera-to-support transforms in the OpenCV convention (+z forward, +x right, +y down).
"""

from dataclasses import dataclass

import numpy as np
import open3d as o3d

from skt_lib.geometry.convex import Mesh


@dataclass(frozen=True)
class Camera:
    eye: np.ndarray  # (3,) support frame
    target: np.ndarray  # (3,)

    def pose(self) -> np.ndarray:
        """Camera-to-support 4×4 (OpenCV axes)."""
        z = self.target - self.eye
        z /= np.linalg.norm(z)
        x = np.cross(z, [0.0, 0.0, 1.0])
        x /= np.linalg.norm(x)
        y = np.cross(z, x)
        t = np.eye(4)
        t[:3, :3] = np.stack([x, y, z], axis=1)
        t[:3, 3] = self.eye
        return t


def viewpoints(target: np.ndarray, distance: float, azimuth_deg, elevation_deg,
               n_azimuth: int, n_elevation: int) -> list[Camera]:
    az = np.radians(np.linspace(*azimuth_deg, n_azimuth))
    el = np.radians(np.linspace(*elevation_deg, n_elevation))
    cams = []
    for e in el:
        for a in az:
            d = np.array([np.cos(e) * np.cos(a), np.cos(e) * np.sin(a), np.sin(e)])
            cams.append(Camera(np.asarray(target, float) + distance * d, np.asarray(target, float)))
    return cams


class DepthRenderer:
    """Ray-casts one mesh; returns the 3D points (support frame) the camera sees."""

    def __init__(self, mesh: Mesh, fov_deg: float):
        self.scene = o3d.t.geometry.RaycastingScene()
        self.scene.add_triangles(o3d.core.Tensor(mesh.vertices.astype(np.float32)),
                                 o3d.core.Tensor(mesh.faces.astype(np.uint32)))
        self.fov_deg = fov_deg

    def points(self, cam: Camera, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
        """(hit points (K, 3) float64 in image order, unit ray directions (K, 3))."""
        rays = o3d.t.geometry.RaycastingScene.create_rays_pinhole(
            fov_deg=self.fov_deg, center=cam.target.tolist(), eye=cam.eye.tolist(),
            up=[0.0, 0.0, 1.0], width_px=width, height_px=height)
        hit = self.scene.cast_rays(rays)["t_hit"].numpy().reshape(-1)
        r = rays.numpy().reshape(-1, 6).astype(np.float64)
        ok = np.isfinite(hit)
        d = r[ok, 3:]
        norm = np.linalg.norm(d, axis=1, keepdims=True)
        return r[ok, :3] + d * hit[ok, None], d / norm

    def distance(self, points: np.ndarray) -> np.ndarray:
        """Unsigned distance of ``points (N, 3)`` to the mesh surface."""
        return self.scene.compute_distance(o3d.core.Tensor(points.astype(np.float32))).numpy()
