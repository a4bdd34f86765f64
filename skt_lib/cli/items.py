"""Supports and objects by name for ``skt hang``: generated ones (``mesh_gen`` ids, with
their pipeline artifacts) and imported ones (``data/user/{supports,objects}/<name>/``,
written by ``skt import-support`` / ``skt import-object``)."""

import json
from pathlib import Path

import numpy as np

from skt_lib.errors import DataError, InputError
from skt_lib.eval.protocol import TestObject, TestSupport
from skt_lib.geometry.export import read_obj
from skt_lib.geometry.se3 import pose_matrix
from skt_lib.geometry.skt import resample
from skt_lib.io import read_table
from skt_lib.perception.render import DepthRenderer
from skt_lib.perception.views import render_view, support_cameras
from skt_lib.schemas import KEYPOINTS, OBJECTS, SKTS, SUPPORTS
from skt_lib.seeding import item_rng
from skt_lib.sim.grasp import grasp_candidates

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
        return json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as err:
        raise DataError(f"{path}: unreadable import record: {err}") from None


def find_support(name: str, root: Path, params) -> TestSupport:
    T = params.clustering.T
    d = user_dir(root, "support", name)
    if (d / SUPPORT_RECORD).is_file():
        rec = _record(d / SUPPORT_RECORD)
        mesh, urdf = str(d / "visual.obj"), str(d / f"{name}.urdf")
        gt, *others = [resample(np.asarray(k, float), T) for k in rec.get("skts", [rec["gt_skt"]])]
        cloud, view = render_cloud(mesh, name, params)
        return TestSupport(name, rec.get("difficulty", "user"), "user", urdf, mesh, gt, cloud,
                           view, tuple(others))
    mg = root / "mesh_gen"
    supports = read_table(mg / "supports.parquet", SUPPORTS).set_index("support_id")
    if name not in supports.index:
        raise InputError(f"{name}: no such support: neither a mesh_gen id in "
                         f"{mg / 'supports.parquet'} nor an import in {d}")
    s = supports.loc[name]
    skts = read_table(root / "rrt_skts" / "skts.parquet", SKTS)
    mine = skts[skts["support_id"] == name].sort_values("skt_index")
    if mine.empty:
        raise InputError(f"{name}: has no ground-truth SKT in {root / 'rrt_skts' / 'skts.parquet'} "
                         "(the planner failed on it); pick another support")
    gt, *others = [resample(np.stack(k), T) for k in mine["keypoints"]]
    mesh = str(mg / s["mesh_path"])
    cloud, view = render_cloud(mesh, name, params)
    return TestSupport(name, s["difficulty"], s["family"], str(mg / s["urdf_path"]), mesh, gt,
                       cloud, view, tuple(others))


def test_object(object_id: str, category: str, urdf: str, mesh_path: str, keypoint: np.ndarray,
                params) -> TestObject:
    """An object as ``sim_eval`` sets it up: grasp candidates and radius from its mesh."""
    p = params.sim_eval
    (mesh,) = read_obj(mesh_path)
    grasps = grasp_candidates(mesh.vertices, keypoint, tuple(p.grasp_pitch_deg), p.grasp_rolls_deg,
                              yaws_deg=p.grasp_yaws_deg)
    radius = float(np.linalg.norm(mesh.vertices - keypoint[:3, 3], axis=1).max())
    return TestObject(object_id, category, urdf, mesh_path, keypoint, grasps, radius)


def find_object(name: str, root: Path, params) -> TestObject:
    d = user_dir(root, "object", name)
    if (d / OBJECT_RECORD).is_file():
        rec = _record(d / OBJECT_RECORD)
        return test_object(name, "user", str(d / f"{name}.urdf"), str(d / "visual.obj"),
                           np.asarray(rec["keypoint"], float).reshape(4, 4), params)
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

