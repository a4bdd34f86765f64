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
