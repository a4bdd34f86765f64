"""tools/object_sweeps.py: objects swept along every stored SKT."""

import json

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq
import pytest

from skt_lib.io import read_table
from skt_lib.schemas import SUPPORTS
from tools.object_sweeps import main, summarise, train_order


def _sweep(kind, oid, skt, mm, at=None):
    return {"object_id": oid, "kind": kind, "skt": skt, "clearance_m": mm / 1000, "deepest_at": at}


def test_training_sweeps_order_the_skts():
    sweeps = [_sweep("train", "a", 0, -5), _sweep("train", "b", 0, 1),  # one clear
              _sweep("train", "a", 1, -1), _sweep("train", "b", 1, -2),  # both clear
              _sweep("train", "a", 2, -2.5), _sweep("train", "b", 2, 2)]  # both clear, shallower min
    assert train_order(sweeps) == [1, 2, 0]
    # test objects do not enter the order
    assert train_order(sweeps + [_sweep("test", "t", 0, 5), _sweep("test", "t", 1, -9),
                                 _sweep("test", "t", 2, -9)]) == [1, 2, 0]


def test_summary_counts_each_pair_once():
    result = {"support_id": "s", "sweeps": [
        _sweep("train", "a", 0, -5), _sweep("train", "a", 1, 1),
        _sweep("test", "t", 0, -4, at=1.0), _sweep("test", "t", 1, 0),  # at the hang, SKT 1 clears
        _sweep("test", "u", 0, -9, at=0.2), _sweep("test", "u", 1, -9),  # nothing clears
        _sweep("test", "v", 0, 0, at=0.5), _sweep("test", "v", 1, -3.5)]}  # SKT 0 only
    s = summarise([result])
    assert s["n_pairs"] == 3
    assert s["test_sweep_clear_rate"] == pytest.approx(1 / 3)
    assert s["clear_rate_ordered_by_train_objects"] == pytest.approx(1 / 3)  # SKT 1 first: t, not v
    assert s["clear_rate_best_stored_skt"] == pytest.approx(2 / 3)
    assert s["failing_pairs_deepest_at"] == {"hang": 1, "first_half": 1, "second_half": 0}


def test_skt0_reproduces_the_stage_metric(tiny_dataset, tmp_path):
    """SKT 0's test-object sweeps are rrt_skts' own: the same rate and median, recomputed."""
    params, data, reports = tiny_dataset
    out = tmp_path / "sweeps.json"
    assert main(["--params", str(params), "--data-root", str(data), "--out", str(out)]) == 0
    got = json.loads(out.read_text())
    stage = json.loads((reports / "rrt_skts" / "metrics.json").read_text())
    assert got["summary"]["n_pairs"] == stage["test_sweep_n_pairs"] > 0
    assert got["summary"]["test_sweep_clear_rate"] == pytest.approx(stage["test_sweep_clear_rate"])
    skt0 = sorted(1000 * s["clearance_m"] for r in got["supports"] for s in r["sweeps"]
                  if s["kind"] == "test" and s["skt"] == 0)
    n = len(skt0)
    median = (skt0[(n - 1) // 2] + skt0[n // 2]) / 2
    assert median == pytest.approx(stage["test_sweep_clearance_mm_median"], abs=1e-9)
    assert all(0.0 <= s["deepest_at"] <= 1.0 for r in got["supports"] for s in r["sweeps"]
               if s["kind"] == "test" and s["skt"] == 0)


def test_no_skts_of_the_split_is_refused(tiny_dataset, tmp_path, capsys):
    params, data, _ = tiny_dataset
    root = tmp_path / "data"
    for stage in ("mesh_gen", "rotation_extraction", "contact_sim"):
        (root / stage).parent.mkdir(parents=True, exist_ok=True)
        (root / stage).symlink_to(data / stage)
    skts = pq.read_table(data / "rrt_skts" / "skts.parquet")
    supports = read_table(data / "mesh_gen" / "supports.parquet", SUPPORTS)
    train = supports[supports["split"] == "train"]["support_id"].tolist()
    train_only = skts.filter(pc.is_in(skts["support_id"], value_set=pa.array(train)))
    assert 0 < train_only.num_rows < skts.num_rows
    (root / "rrt_skts").mkdir()
    pq.write_table(train_only, root / "rrt_skts" / "skts.parquet")
    assert main(["--params", str(params), "--data-root", str(root)]) == 2
    assert "no SKTs of a test support" in capsys.readouterr().err
