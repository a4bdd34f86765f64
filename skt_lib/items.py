"""The supports and objects a trial runs on, as records (:class:`TestSupport`,
:class:`TestObject`), and finding them by name: generated ones (``mesh_gen`` ids, with their
pipeline artifacts) and imported ones — the user-item store,
``<data-root>/user/{supports,objects}/<name>/``, written by ``skt import-support`` /
``skt import-object`` and read by ``skt hang`` and ``sim_eval.extra_supports`` /
``extra_objects`` alike."""

import json
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from skt_lib.errors import DataError, InputError
from skt_lib.geometry.export import read_obj
from skt_lib.geometry.se3 import pose_matrix
from skt_lib.geometry.skt import resample
from skt_lib.io import read_table
from skt_lib.perception.render import DepthRenderer
from skt_lib.perception.views import render_view, support_cameras
from skt_lib.schemas import KEYPOINTS, OBJECTS, SKTS, SUPPORTS
from skt_lib.seeding import item_rng
from skt_lib.sim.grasp import Grasp, grasp_candidates


@dataclass(frozen=True, eq=False)
class TestSupport:
    support_id: str
    difficulty: str
    family: str
    urdf: str
    mesh: str
    gt: np.ndarray | None  # (T, 3) ground-truth SKT, ξ_0 first; None: none stored (skt hang only)
    cloud: np.ndarray  # (N, 3) the view the methods see
    view: int
    others: tuple[np.ndarray, ...] = ()  # the support's further stored SKTs (T, 3), in order


@dataclass(frozen=True, eq=False)
class TestObject:
    object_id: str
    category: str
    urdf: str
    mesh: str
    keypoint: np.ndarray  # (4, 4) keypoint frame in the object frame
    grasps: tuple[Grasp, ...]  # grasp candidates (grasp target in the keypoint frame), in order
    radius_m: float  # farthest object point from the keypoint


USER = "user"
SUPPORT_RECORD, OBJECT_RECORD = "support.json", "object.json"


def user_dir(root: Path, kind: str, name: str) -> Path:
    """``<root>/user/<kind>s/<name>``: where an imported support or object lives."""
    return Path(root) / USER / f"{kind}s" / name


def render_cloud(mesh_path: str, support_id: str, params) -> tuple[np.ndarray, int]:
    """One rendered view of a support, as ``sim_eval`` gives the methods: the view index
    drawn by ``item_rng(seed, "sim_eval", support_id)``, rendered as ``render_views`` does."""
    (mesh,) = read_obj(mesh_path)
    p = params.render_views
    cams = support_cameras(mesh, p)
    view = int(item_rng(params.common.seed, "sim_eval", support_id).integers(len(cams)))
    rng = item_rng(params.common.seed, "render_views", f"{support_id}/{view}")
    points, *_ = render_view(DepthRenderer(mesh, p.fov_deg), cams[view], p, rng,
                             f"{support_id} view {view}")
    return points, view


def _record(path: Path) -> dict:
    try:
        rec = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise DataError(f"{path}: unreadable import record: {err}") from None
    if not isinstance(rec, dict):
        raise DataError(f"{path}: not an import record (a JSON object); re-import the item")
    return rec


def _array(value, path: Path, key: str, waypoints: bool) -> np.ndarray:
    """A value of an import record: ``waypoints`` — ``(n ≥ 2, 3)`` finite floats; else a 4×4
    matrix, as 16 finite floats (rows) or 4 rows of 4. :class:`DataError` naming the record
    and key otherwise."""
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        a = np.zeros(0)
    if waypoints:
        ok = a.ndim == 2 and a.shape[1] == 3 and len(a) >= 2
    else:
        ok = a.size == 16 and a.ndim in (1, 2)
        a = a.reshape(4, 4) if ok else a
    if not ok or not np.isfinite(a).all():
        want = "a list of [x, y, z] waypoints" if waypoints else "a finite 4×4 matrix"
        raise DataError(f"{path}: {key!r} is not {want} (re-import the item)")
    return a


def find_support(name: str, root: Path, params, gt_for: str | None = "") -> TestSupport:
    """The support ``name``: an import in ``<root>/user/supports/`` or a ``mesh_gen`` id, with
    its stored SKTs resampled to ``clustering.T`` (the first is the ground truth) and the view
    the methods see (:func:`render_cloud`).

    A support without a stored SKT raises :class:`InputError` naming ``gt_for`` (what needs
    the ground truth); with ``gt_for=None`` it comes back with ``gt`` None (for methods that
    never look at the ground truth)."""
    T = params.clustering.T
    d = user_dir(root, "support", name)
    if (d / SUPPORT_RECORD).is_file():
        rec = _record(d / SUPPORT_RECORD)
        mesh, urdf = str(d / "visual.obj"), str(d / f"{name}.urdf")
        stored = [_array(k, d / SUPPORT_RECORD, "skts", True)
                  for k in rec.get("skts") or ([rec["gt_skt"]] if rec.get("gt_skt") else [])]
        where = f"{d / SUPPORT_RECORD} (no 'skts')"
        difficulty, family = rec.get("difficulty", "user"), "user"
    else:
        mg = root / "mesh_gen"
        supports = read_table(mg / "supports.parquet", SUPPORTS).set_index("support_id")
        if name not in supports.index:
            raise InputError(f"{name}: no such support: neither a mesh_gen id in "
                             f"{mg / 'supports.parquet'} nor an import in {d}")
        s = supports.loc[name]
        skts = read_table(root / "rrt_skts" / "skts.parquet", SKTS)
        stored = [np.stack(k) for k in
                  skts[skts["support_id"] == name].sort_values("skt_index")["keypoints"]]
        where = f"{root / 'rrt_skts' / 'skts.parquet'} (the planner failed on it)"
        mesh, urdf = str(mg / s["mesh_path"]), str(mg / s["urdf_path"])
        difficulty, family = s["difficulty"], s["family"]
    if not stored and gt_for is not None:
        raise InputError(f"{name}: has no ground-truth SKT in {where}"
                         + (f"; {gt_for}" if gt_for else "; pick another support"))
    gt, *others = [resample(k, T) for k in stored] or [None]
    cloud, view = render_cloud(mesh, name, params)
    return TestSupport(name, difficulty, family, urdf, mesh, gt, cloud, view, tuple(others))


def test_object(object_id: str, category: str, urdf: str, mesh_path: str, keypoint: np.ndarray,
                params) -> TestObject:
    """An object as ``sim_eval`` sets it up: grasp candidates and radius from its mesh."""
    p = params.sim_eval
    (mesh,) = read_obj(mesh_path)
    grasps = grasp_candidates(mesh.vertices, keypoint, tuple(p.grasp_pitch_deg), p.grasp_rolls_deg,
                              yaws_deg=p.grasp_yaws_deg, sphere=p.grasp_sphere_directions)
    radius = float(np.linalg.norm(mesh.vertices - keypoint[:3, 3], axis=1).max())
    return TestObject(object_id, category, urdf, mesh_path, keypoint, grasps, radius)


def find_object(name: str, root: Path, params) -> TestObject:
    d = user_dir(root, "object", name)
    if (d / OBJECT_RECORD).is_file():
        rec = _record(d / OBJECT_RECORD)
        return test_object(name, "user", str(d / f"{name}.urdf"), str(d / "visual.obj"),
                           _array(rec.get("keypoint"), d / OBJECT_RECORD, "keypoint", False),
                           params)
    mg = root / "mesh_gen"
    objects = read_table(mg / "objects.parquet", OBJECTS).set_index("object_id")
    if name not in objects.index:
        raise InputError(f"{name}: no such object: neither a mesh_gen id in "
                         f"{mg / 'objects.parquet'} nor an import in {d}")
    kps = read_table(root / "rotation_extraction" / "keypoints.parquet", KEYPOINTS)
    kps = kps.set_index("object_id")
    if name not in kps.index:
        raise InputError(f"{name}: has no keypoint (it did not hang on the rod in contact_sim)")
    o, k = objects.loc[name], kps.loc[name]
    return test_object(name, o["category"], str(mg / o["urdf_path"]), str(mg / o["mesh_path"]),
                       pose_matrix(k["position"], k["quat"]), params)

