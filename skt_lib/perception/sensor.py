"""A depth camera's view of a support on its wall: what a real sensor returns, not a perfect
ray cast.

:class:`CameraScene` ray-casts the support mesh and the wall behind it (the plane x = 0 of
the support frame) into a depth image; :func:`sense` turns that image into the cloud a
structured-light or active-stereo camera would give, in the camera frame (OpenCV axes: +x
right, +y down, +z forward), and :func:`camera_view` also draws the error of the
camera-to-support transform a user would assume. The effects, in the order they act:

1. **Missing returns at grazing angles**: a pixel whose surface is seen more than
   ``grazing_deg[0]`` off its normal is dropped with a probability rising linearly to 1 at
   ``grazing_deg[1]`` (the projected pattern is too stretched to match).
2. **Parts thinner than the matching window**: along each image row, a run of pixels of one
   surface (no depth jump over ``edge_jump_m``) shorter than ``min_run_px`` is dropped —
   stereo matching cannot lock onto a part narrower than its window.
3. **Flying pixels**: a share ``flying_rate`` of the pixels at a depth edge take a depth
   between their own and their neighbour's across the edge (mixed returns).
4. **Depth noise growing with range**: σ(z) = ``sigma_a_m`` + ``sigma_b_per_m`` · z² on the
   depth z (the point moves along its ray, up to 6 % farther at the image corners). The z²
   term is the stereo depth error, RMS = z² · subpixel / (focal_px ·
   baseline) (Intel RealSense D400 tuning guide: subpixel 0.08, focal 640 px, baseline 50 mm
   give 0.0025 m⁻¹); the constant is a calibration floor. At 0.35–0.5 m: 0.8–1.1 mm,
   the range Nguyen, Izadi & Lovell (3DIMPVT 2012) measured for the Kinect's axial noise.
5. **Quantization**: depth rounded to ``quant_m`` (a 16-bit depth image in millimetres).
6. **Camera pose error** (:func:`camera_view`): the assumed camera-to-support transform is
   the true one moved by ``pose_t_m`` along a random direction and turned by ``pose_r_deg``
   about a random axis.

:meth:`SensorModel.at` scales every effect but the quantization with a severity: 0 is a
perfect sensor, 1 the defaults above, 2–4 a worse camera or setup.
"""

from dataclasses import dataclass, replace

import numpy as np
import open3d as o3d
from scipy.spatial.transform import Rotation

from skt_lib.geometry.convex import Mesh

#: Half-extent (m) of the wall quad behind the support: past every view's frustum.
WALL_HALF_M = 2.0
WALL_ID, SUPPORT_ID = 0, 1


@dataclass(frozen=True)
class SensorModel:
    sigma_a_m: float = 0.0005
    sigma_b_per_m: float = 0.0025
    quant_m: float = 0.001
    grazing_deg: tuple[float, float] = (70.0, 85.0)
    min_run_px: int = 2
    edge_jump_m: float = 0.005
    flying_rate: float = 0.03
    pose_t_m: float = 0.01
    pose_r_deg: float = 2.0

    def at(self, severity: float) -> "SensorModel":
        """This model with every effect but the quantization scaled by ``severity`` (0 = a
        perfect sensor, quantization off too)."""
        if severity < 0:
            raise ValueError(f"severity: must be >= 0, got {severity}")
        if severity == 0:
            return SensorModel(0.0, 0.0, 0.0, (90.0, 90.0), 1, self.edge_jump_m, 0.0, 0.0, 0.0)
        lo, hi = self.grazing_deg
        shift = (severity - 1) * 5.0  # each step past 1 loses returns 5° sooner (not below 0°)
        return replace(
            self, sigma_a_m=self.sigma_a_m * severity, sigma_b_per_m=self.sigma_b_per_m * severity,
            quant_m=self.quant_m,
            grazing_deg=(float(np.clip(lo - shift, 0.0, 90.0)),
                         float(np.clip(hi - shift, 0.0, 90.0))),
            min_run_px=max(1, round(self.min_run_px * severity)),
            flying_rate=min(1.0, self.flying_rate * severity), pose_t_m=self.pose_t_m * severity,
            pose_r_deg=self.pose_r_deg * severity)


@dataclass(frozen=True)
class Intrinsics:
    width: int
    height: int
    fov_deg: float  # vertical field of view

    @property
    def focal_px(self) -> float:
        return (self.height / 2) / np.tan(np.radians(self.fov_deg) / 2)

    def directions(self) -> np.ndarray:
        """``(H, W, 3)`` camera-frame rays through pixel centres, scaled to z = 1."""
        u = (np.arange(self.width) + 0.5 - self.width / 2) / self.focal_px
        v = (np.arange(self.height) + 0.5 - self.height / 2) / self.focal_px
        uu, vv = np.meshgrid(u, v)
        return np.stack([uu, vv, np.ones_like(uu)], axis=-1)


@dataclass(frozen=True, eq=False)
class DepthImage:
    depth: np.ndarray  # (H, W) metres along the optical axis, inf where nothing is hit
    cos_incidence: np.ndarray  # (H, W) |cos| of the angle between ray and surface normal
    label: np.ndarray  # (H, W) WALL_ID, SUPPORT_ID, or -1 where nothing is hit


class CameraScene:
    """A support mesh (support frame) in front of its wall, for depth images."""

    def __init__(self, mesh: Mesh, wall: bool = True):
        self.scene = o3d.t.geometry.RaycastingScene()
        ids = {}
        if wall:
            h = WALL_HALF_M
            quad = np.array([[0, -h, -h], [0, h, -h], [0, h, h], [0, -h, h]], np.float32)
            ids[self._add(quad, np.array([[0, 1, 2], [0, 2, 3]]))] = WALL_ID
        ids[self._add(mesh.vertices, mesh.faces)] = SUPPORT_ID
        self.labels = ids

    def _add(self, vertices: np.ndarray, faces: np.ndarray) -> int:
        return self.scene.add_triangles(o3d.core.Tensor(np.asarray(vertices, np.float32)),
                                        o3d.core.Tensor(np.asarray(faces, np.uint32)))

    def depth(self, pose: np.ndarray, k: Intrinsics) -> DepthImage:
        """The depth image of a camera at ``pose`` (camera-to-support, OpenCV axes)."""
        d_cam = k.directions()
        d = d_cam @ pose[:3, :3].T
        rays = np.concatenate([np.broadcast_to(pose[:3, 3], d.shape), d], axis=-1)
        hit = self.scene.cast_rays(o3d.core.Tensor(rays.astype(np.float32)))
        t = hit["t_hit"].numpy().astype(np.float64)  # rays have z = 1: t is the depth
        normal = hit["primitive_normals"].numpy().astype(np.float64)
        unit = d / np.linalg.norm(d, axis=-1, keepdims=True)
        cos = np.abs((normal * unit).sum(-1))
        geom = hit["geometry_ids"].numpy()
        label = np.full(t.shape, -1, np.int64)
        for gid, lab in self.labels.items():
            label[(geom == gid) & np.isfinite(t)] = lab
        return DepthImage(t, cos, label)


def sense(img: DepthImage, k: Intrinsics, model: SensorModel, rng: np.random.Generator
          ) -> tuple[np.ndarray, np.ndarray]:
    """(points (K, 3) camera frame, labels (K,)) a sensor ``model`` returns for ``img``."""
    z = img.depth.copy()
    valid = np.isfinite(z)
    lo, hi = np.radians(model.grazing_deg)
    angle = np.arccos(np.clip(img.cos_incidence, 0.0, 1.0))
    if hi > lo:
        p_drop = np.clip((angle - lo) / (hi - lo), 0.0, 1.0)
        valid &= rng.random(z.shape) >= p_drop
    else:  # no ramp: a hard cut
        valid &= angle <= lo
    z[~valid] = np.inf
    valid &= _long_runs(z, model.edge_jump_m, model.min_run_px)
    z[~valid] = np.inf
    z = _flying_pixels(z, model, rng)
    valid = np.isfinite(z)
    zv = z[valid]
    zv = zv + rng.normal(0.0, 1.0, zv.shape) * (model.sigma_a_m + model.sigma_b_per_m * zv ** 2)
    if model.quant_m > 0:
        zv = np.round(zv / model.quant_m) * model.quant_m
    points = k.directions()[valid] * zv[:, None]
    return points, img.label[valid]


def _long_runs(z: np.ndarray, jump: float, min_run: int) -> np.ndarray:
    """``(H, W)`` bool: pixels on a row run of one surface at least ``min_run`` long."""
    if min_run <= 1:
        return np.isfinite(z)
    finite = np.isfinite(z)
    step = np.abs(np.diff(np.where(finite, z, 0.0), axis=1))
    same = finite[:, 1:] & finite[:, :-1] & (step < jump)
    h, w = z.shape
    # a run starts at column 0 and wherever a pixel is not of one surface with its left one
    starts = np.concatenate([np.ones((h, 1), bool), ~same], axis=1)
    run = np.cumsum(starts.ravel()).reshape(h, w)  # the run id of every pixel, row-major
    return finite & (np.bincount(run.ravel())[run] >= min_run)


def _flying_pixels(z: np.ndarray, model: SensorModel, rng: np.random.Generator) -> np.ndarray:
    """``z`` with a share of the edge pixels moved toward their neighbour across the edge."""
    if model.flying_rate <= 0:
        return z
    out = z.copy()
    h, w = z.shape
    # the neighbour right, left, below, above of every pixel (inf off the image)
    pad = np.pad(z, 1, constant_values=np.inf)
    neighbours = np.stack([pad[1:-1, 2:], pad[1:-1, :-2], pad[2:, 1:-1], pad[:-2, 1:-1]])
    with np.errstate(invalid="ignore"):  # inf - inf: no return on either side
        jump = np.abs(neighbours - z)
    jump[~np.isfinite(jump)] = 0.0
    edge = np.isfinite(z) & (jump.max(0) > model.edge_jump_m)
    fly = edge & (rng.random((h, w)) < model.flying_rate)
    far = neighbours[jump.argmax(0), np.arange(h)[:, None], np.arange(w)[None, :]]
    lam = rng.random((h, w))
    out[fly] = z[fly] + lam[fly] * (far[fly] - z[fly])
    return out


def pose_error(model: SensorModel, rng: np.random.Generator) -> np.ndarray:
    """A 4×4 error transform: ``pose_t_m`` along a random direction after a turn of
    ``pose_r_deg`` about a random axis."""
    e = np.eye(4)
    axis = rng.normal(size=3)
    rotvec = np.radians(model.pose_r_deg) * axis / np.linalg.norm(axis)
    e[:3, :3] = Rotation.from_rotvec(rotvec).as_matrix()
    t = rng.normal(size=3)
    e[:3, 3] = model.pose_t_m * t / np.linalg.norm(t)
    return e


@dataclass(frozen=True, eq=False)
class CameraView:
    points: np.ndarray  # (K, 3) camera frame (OpenCV), metres
    labels: np.ndarray  # (K,) WALL_ID or SUPPORT_ID: where each return came from
    pose: np.ndarray  # (4, 4) the true camera-to-support transform
    assumed: np.ndarray  # (4, 4) the transform a user would assume (pose error applied)


def camera_view(scene: CameraScene, pose: np.ndarray, k: Intrinsics, model: SensorModel,
                rng: np.random.Generator) -> CameraView:
    """One view: the sensor's cloud of ``scene`` from a camera at ``pose`` and the pose a user
    would assume for it."""
    points, labels = sense(scene.depth(pose, k), k, model, rng)
    return CameraView(points, labels, pose, pose @ pose_error(model, rng))
