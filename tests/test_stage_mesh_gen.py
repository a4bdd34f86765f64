"""mesh_gen end to end on tiny params: contract, byte-identical reruns, worker-count independence."""

import json
import subprocess
import sys
from pathlib import Path

import pytest

from skt_lib.config import LEVELS, OBJECT_CATEGORIES
from skt_lib.errors import ParamsError
from skt_lib.geometry.checks import check_parts, check_solid
from skt_lib.geometry.export import read_obj
from skt_lib.io import read_table
from skt_lib.schemas import OBJECTS, SUPPORTS
from stages import mesh_gen


def _run(tmp_path, write_params, params, name, fresh_process=False):
    """mesh_gen on ``params``; ``fresh_process`` runs it as ``python -m stages.mesh_gen``.

    A process pool forked from this process after an in-process run can hang: manifold3d's
    TBB thread pool does not survive a fork (the workers wait on threads the child lacks).
    The stage itself always starts from a fresh interpreter (dvc), so a run with workers
    does too here."""
    path = write_params(params, f"{name}.yaml")
    data, rep = tmp_path / name / "data", tmp_path / name / "reports"
    argv = ["--params", str(path), "--data-dir", str(data), "--reports-dir", str(rep)]
    if fresh_process:
        done = subprocess.run([sys.executable, "-m", "stages.mesh_gen", *argv],
                              cwd=Path(__file__).resolve().parents[1],
                              capture_output=True, text=True)
        assert done.returncode == 0, done.stderr[-3000:]
    else:
        assert mesh_gen.main(argv) == 0
    return data, rep


def _files(root):
    return {p.relative_to(root): p.read_bytes() for p in sorted(root.rglob("*"))
            if p.is_file() and p.suffix in {".parquet", ".obj", ".urdf"}}


@pytest.mark.slow
def test_contract_and_determinism(tmp_path, write_params, tiny_dict):
    data, rep = _run(tmp_path, write_params, tiny_dict, "a")
    supports = read_table(data / "supports.parquet", SUPPORTS)
    objects = read_table(data / "objects.parquet", OBJECTS)
    metrics = json.loads((rep / "metrics.json").read_text())

    assert metrics["n_supports"] == len(supports) == 12
    assert metrics["n_objects"] == 10 and metrics["n_invalid"] == 0  # 2 per category
    assert set(metrics["supports_by_difficulty"]) == set(LEVELS)
    assert metrics["test_supports_by_difficulty"] == {lv: 1 for lv in LEVELS}
    assert metrics["objects_by_category"] == {c: 2 for c in OBJECT_CATEGORIES}
    assert metrics["test_objects_by_category"] == {c: 1 for c in OBJECT_CATEGORIES}
    assert objects["is_reference"].sum() == 1
    # the split is per category, and the reference only ever makes labels
    real = objects[~objects["is_reference"]]
    assert {c: sorted(g) for c, g in real.groupby("category")["split"]} == {
        c: ["test", "train"] for c in OBJECT_CATEGORIES}
    assert (objects.loc[objects["is_reference"], "split"] == "train").all()
    assert set(supports["split"]) == {"train", "val", "test"}
    assert supports["support_id"].is_unique and objects["object_id"].is_unique

    # every written mesh is a watertight solid covered by its convex parts
    for df in (supports, objects):
        for _, row in df.iterrows():
            (visual,) = read_obj(data / row["mesh_path"])
            check_solid(visual, row["mesh_path"])
            assert check_parts(read_obj(data / row["collision_path"]), visual, "x") >= 0.95
            assert (data / row["urdf_path"]).is_file()
    assert (data / "mesh_gen.rrd").stat().st_size > 10_000
    report = (rep / "report.md").read_text()
    assert "gallery_very_hard.png" in report and (rep / "gallery_very_hard.png").is_file()

    # same seed again, now on 2 workers: byte-identical tables and mesh files
    tiny_dict["compute"]["n_workers"] = 2
    data_b, rep_b = _run(tmp_path, write_params, tiny_dict, "b", fresh_process=True)
    assert _files(data) == _files(data_b)
    assert (rep / "metrics.json").read_bytes() == (rep_b / "metrics.json").read_bytes()

    # another seed: different shapes
    tiny_dict["common"]["seed"] = 8
    data_c, _ = _run(tmp_path, write_params, tiny_dict, "c")
    assert _files(data_c) != _files(data)


@pytest.mark.slow
def test_extra_training_supports_leave_the_split_as_it_was(tmp_path, write_params, tiny_dict):
    """n_extra_train_supports adds supports after the n_supports, all training; every support
    of the run without them comes out byte for byte the same, in the same split."""
    tiny_dict["mesh_gen"]["n_supports"] = 8
    tiny_dict["mesh_gen"]["n_val_per_level"] = 0
    data, _ = _run(tmp_path, write_params, tiny_dict, "plain")
    tiny_dict["mesh_gen"]["n_extra_train_supports"] = 3
    data_x, rep_x = _run(tmp_path, write_params, tiny_dict, "extra")
    plain = read_table(data / "supports.parquet", SUPPORTS).set_index("support_id")
    extra = read_table(data_x / "supports.parquet", SUPPORTS).set_index("support_id")
    assert list(extra.index) == [f"support_{i:05d}" for i in range(11)]
    assert (extra.loc[plain.index, "split"] == plain["split"]).all()
    assert set(extra.loc[~extra.index.isin(plain.index), "split"]) == {"train"}
    files, files_x = _files(data), _files(data_x)
    del files[Path("supports.parquet")]
    assert {k: files_x[k] for k in files} == files  # the same meshes and URDFs, byte for byte
    per_support = sum(k.parts[0] == "supports" for k in files) // 8
    new = {k for k in files_x if k not in files and k != Path("supports.parquet")}
    assert len(new) == 3 * per_support and all(k.parts[0] == "supports" for k in new)
    m = json.loads((rep_x / "metrics.json").read_text())
    assert m["n_extra_train_supports"] == 3 and m["supports_by_split"]["train"] == 11 - 4


def test_bad_params_fail_before_writing(tmp_path, write_params, tiny_dict):
    tiny_dict["mesh_gen"]["n_supports"] = -3
    with pytest.raises(ParamsError, match="mesh_gen.n_supports"):
        _run(tmp_path, write_params, tiny_dict, "bad")
    assert not (tmp_path / "bad" / "data").exists()
