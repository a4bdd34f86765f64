"""Fixtures of the ``skt`` tests: the tiny pipeline's artifacts (session fixture
``tiny_dataset``), a data root where imports may be written, and clouds saved from
``render_views`` in the formats users bring."""

import os
from pathlib import Path

import numpy as np
import open3d as o3d
import pytest

from skt_lib.cli.main import main
from skt_lib.io import read_npz
from skt_lib.perception.views import RENDER_SPEC

STAGES = ("mesh_gen", "contact_sim", "rotation_extraction", "rrt_skts", "render_views",
          "affordance_maps", "clustering", "train", "train_baselines")
ROOT = Path(__file__).resolve().parents[2]
EASY_SUPPORT, OBJECT = "support_00008", "object_mug_000"  # tiny preset: an easy test support


def run_skt(capsys, *args: str) -> tuple[int, str, str]:
    """``skt ARGS`` in this process: (exit code, stdout, stderr)."""
    capsys.readouterr()
    rc = main([str(a) for a in args])
    out, err = capsys.readouterr()
    return rc, out, err


def tree_state(root: Path) -> dict:
    """Every file under ``root`` (links followed) with its size and mtime."""
    out = {}
    for dirpath, _, files in os.walk(root, followlinks=True):
        for f in files:
            p = Path(dirpath) / f
            st = p.stat()
            out[str(p.relative_to(root))] = (st.st_size, st.st_mtime_ns)
    return out


@pytest.fixture(scope="session")
def data_root(tiny_dataset, tmp_path_factory) -> Path:
    """A data root whose stage folders are the tiny pipeline's (linked, read-only by intent)
    and whose ``user/`` is this session's own."""
    _, data, _ = tiny_dataset
    root = tmp_path_factory.mktemp("cli_data")
    for stage in STAGES:
        (root / stage).symlink_to(data / stage, target_is_directory=True)
    return root


@pytest.fixture(scope="session")
def view(tiny_dataset) -> np.ndarray:
    """One rendered view ``(1000, 3)`` float64 of an easy test support, support frame, m."""
    _, data, _ = tiny_dataset
    return read_npz(data / "render_views" / f"{EASY_SUPPORT}.npz", RENDER_SPEC)["points"][5] \
        .astype(np.float64)


def save_ply(path: Path, points: np.ndarray) -> Path:
    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(points, np.float64)))
    assert o3d.io.write_point_cloud(str(path), pcd)
    return path


def camera_cloud(data_root: Path, view: int = 10, severity: float = 1.0
                 ) -> tuple[np.ndarray, np.ndarray]:
    """A depth camera's raw cloud (camera frame, the wall in view, the sensor model at
    ``severity``, 1 its default) of the easy test support, with the true camera-to-support
    pose."""
    from skt_lib.config.params_file import load_params
    from skt_lib.geometry.export import read_obj
    from skt_lib.io import read_table
    from skt_lib.perception.sensor import CameraScene, Intrinsics, SensorModel, camera_view
    from skt_lib.perception.views import support_cameras
    from skt_lib.schemas import SUPPORTS

    p = load_params(ROOT / "params.yaml").render_views
    rows = read_table(data_root / "mesh_gen" / "supports.parquet", SUPPORTS).set_index("support_id")
    (mesh,) = read_obj(data_root / "mesh_gen" / rows.loc[EASY_SUPPORT, "mesh_path"])
    pose = support_cameras(mesh, p)[view].pose()
    seen = camera_view(CameraScene(mesh), pose, Intrinsics(p.width, p.height, p.fov_deg),
                       SensorModel().at(severity), np.random.default_rng(0))
    return seen.points, pose
