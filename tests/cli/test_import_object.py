"""``skt import-object`` on a real asset nobody here made (pybullet_data's mug), then
``skt hang`` of it on a generated easy support by the oracle."""

import json
import os

import numpy as np
import pybullet_data
import pytest

from skt_lib.geometry.export import read_obj
from skt_lib.geometry.objects import aperture_clearance
from tests.cli.conftest import EASY_SUPPORT, run_skt

MUG = os.path.join(pybullet_data.getDataPath(), "objects", "mug.obj")  # mesh of objects/mug.urdf


@pytest.mark.slow
def test_import_the_pybullet_mug_and_hang_it(capsys, tmp_path, data_root, tiny_dataset):
    params = tiny_dataset[0]
    rc, out, err = run_skt(capsys, "import-object", MUG, "--name", "pb_mug", "--params", params,
                           "--data-root", data_root)
    assert rc == 0, err
    d = data_root / "user" / "objects" / "pb_mug"
    rec = json.loads((d / "object.json").read_text())
    parts = read_obj(d / "collision.obj")
    # the object frame of docs/frames.md: a rod along x through the origin passes the handle
    assert aperture_clearance(parts) == pytest.approx(rec["aperture_clearance_m"])
    assert rec["aperture_clearance_m"] >= 0.01  # the handle admits a 1 cm rod
    (visual,) = read_obj(d / "visual.obj")
    assert visual.vertices[:, 2].mean() < 0  # the body hangs below the aperture (+z up)
    assert rec["part_iou"] >= 0.9
    assert len(rec["keypoint"]) == 16
    rc, out, err = run_skt(capsys, "hang", "--support", EASY_SUPPORT, "--object", "pb_mug",
                           "--method", "oracle", "--params", params, "--data-root", data_root,
                           "--rrd", tmp_path / "mug.rrd")
    assert rc == 0, err
    print(f"pybullet mug hang verdict: {out.strip()}")
    assert "pb_mug: " in out and (tmp_path / "mug.rrd").stat().st_size > 10_000
    # the verdict itself is reported, not asserted: it is a fact about the executor
    rc, _, err = run_skt(capsys, "import-object", MUG, "--name", "pb_mug", "--params", params,
                         "--data-root", data_root)
    assert rc == 2 and "already imported" in err


def test_override_of_the_aperture_is_used(capsys, tmp_path, data_root, tiny_dataset):
    """--aperture-point/--aperture-axis through the mug's body (no hole there): the override
    is taken as given, so the rod would pass through solid material and is refused."""
    rc, _, err = run_skt(capsys, "import-object", MUG, "--name", "pb_mug_axis", "--params",
                         tiny_dataset[0], "--data-root", data_root, "--aperture-point", "0", "0",
                         "0.05", "--aperture-axis", "1", "0", "0")
    assert rc == 2 and "admits a rod of radius 0.0 mm" in err, err
    assert not (data_root / "user" / "objects" / "pb_mug_axis").exists()
