"""render_views, affordance_maps, clustering on the tiny dataset."""

import json

import numpy as np
import pytest

from skt_lib.io import read_npz, read_table
from skt_lib.perception.views import RENDER_SPEC
from skt_lib.schemas import LABELS, SUPPORTS
from stages import clustering, render_views

pytestmark = pytest.mark.slow


def _rerun(stage, tiny_dataset, tmp_path):
    params, data, _ = tiny_dataset
    name = stage.__name__.rsplit(".", 1)[-1]
    out = tmp_path / name
    assert stage.main(["--params", str(params), "--data-root", str(data), "--data-dir", str(out),
                       "--reports-dir", str(tmp_path / "rep")]) == 0
    return data / name, out


def test_render_contract_and_determinism(tiny_dataset, tmp_path):
    _, data, reports = tiny_dataset
    m = json.loads((reports / "render_views" / "metrics.json").read_text())
    assert m["views_per_support"] == 42 and m["points_per_view"] == 1000
    assert m["on_surface_rate"] == 1.0
    supports = read_table(data / "mesh_gen" / "supports.parquet", SUPPORTS)
    for sid in supports["support_id"]:
        z = read_npz(data / "render_views" / f"{sid}.npz", RENDER_SPEC)
        assert z["points"].shape == (42, 1000, 3) and np.isfinite(z["points"]).all()
        assert z["cameras"].shape == (42, 4, 4)
        assert all(len(np.unique(v, axis=0)) == n for v, n in zip(z["points"], z["n_visible"]))
    first, again = _rerun(render_views, tiny_dataset, tmp_path)
    for sid in supports["support_id"]:
        assert (first / f"{sid}.npz").read_bytes() == (again / f"{sid}.npz").read_bytes()


def test_affordance_contract(tiny_dataset):
    _, data, reports = tiny_dataset
    m = json.loads((reports / "affordance_maps" / "metrics.json").read_text())
    assert m["n_views"] == 42 * m["n_supports"]
    assert m["argmax_within_1cm_rate"] >= 0.95 and m["contact_visible_rate"] > 0.5
    sid = read_table(data / "mesh_gen" / "supports.parquet", SUPPORTS)["support_id"][0]
    z = read_npz(data / "affordance_maps" / f"{sid}.npz",
                 {"affordance": ("float32", 2), "contact_index": ("int32", 1)})
    assert z["affordance"].shape == (42, 1000)
    assert 0 <= z["affordance"].min() and z["affordance"].max() <= 1.0 + 1e-6
    # the label is not in the point order: contact points sit anywhere in the cloud
    assert len(np.unique(z["contact_index"])) > 1 or z["contact_index"][0] != 0


def test_clustering_contract_and_determinism(tiny_dataset, tmp_path):
    _, data, reports = tiny_dataset
    m = json.loads((reports / "clustering" / "metrics.json").read_text())
    assert m["k"] == 3 and len(m["cluster_sizes"]) == 3 and min(m["cluster_sizes"]) > 0
    assert -1 <= m["silhouette"] <= 1
    labels = read_table(data / "clustering" / "labels.parquet", LABELS)
    assert set(labels["category"]) <= {0, 1, 2} and labels["is_template"].sum() >= 1
    z = read_npz(data / "clustering" / "templates.npz", {"templates": ("float64", 3)})
    assert z["templates"].shape == (3, 10, 3) and np.allclose(z["templates"][:, 0], 0)
    first, again = _rerun(clustering, tiny_dataset, tmp_path)
    assert (first / "labels.parquet").read_bytes() == (again / "labels.parquet").read_bytes()
    assert (first / "templates.npz").read_bytes() == (again / "templates.npz").read_bytes()
