"""render_views, affordance_maps, clustering on the tiny dataset."""

import json

import numpy as np
import pytest
import trimesh

from skt_lib.config.params_file import load_params
from skt_lib.io import read_npz, read_table
from skt_lib.labels.affordance import hanging_part, segmentation_map_naive
from skt_lib.perception.views import RENDER_SPEC
from skt_lib.schemas import CONTACTS, LABELS, SKTS, SUPPORTS
from stages import clustering, render_views
from tests.conftest import TINY

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
    supports = read_table(data / "mesh_gen" / "supports.parquet", SUPPORTS)
    assert m["n_supports"] == len(supports) and m["n_failed"] == 0 and m["failures_by_reason"] == {}
    # independent of the renderer (Open3D): trimesh's ray caster from the camera centre
    # must hit the support first exactly at each rendered point (on the surface and visible)
    sid = supports["support_id"][0]
    mesh = trimesh.load(data / "mesh_gen" / supports["mesh_path"][0], force="mesh", process=False)
    tris = np.asarray(mesh.vertices)[np.asarray(mesh.faces)]
    z = read_npz(data / "render_views" / f"{sid}.npz", RENDER_SPEC)
    for v in (0, 17, 41):
        pts = z["points"][v][::25].astype(np.float64)
        eye, rot = z["cameras"][v][:3, 3].astype(np.float64), z["cameras"][v][:3, :3]
        assert ((pts - eye) @ rot)[:, 2].min() > 0  # in front of the camera (OpenCV +z)
        dist = np.linalg.norm(pts - eye, axis=1)
        first = _first_hit(eye, (pts - eye) / dist[:, None], tris)
        assert np.abs(first - dist).max() < 1e-4
    for sid in supports["support_id"]:
        z = read_npz(data / "render_views" / f"{sid}.npz", RENDER_SPEC)
        assert z["points"].shape == (42, 1000, 3) and np.isfinite(z["points"]).all()
        assert z["cameras"].shape == (42, 4, 4)
        assert all(len(np.unique(v, axis=0)) == n for v, n in zip(z["points"], z["n_visible"]))
    first, again = _rerun(render_views, tiny_dataset, tmp_path)
    for sid in supports["support_id"]:
        assert (first / f"{sid}.npz").read_bytes() == (again / f"{sid}.npz").read_bytes()


def test_affordance_contract(tiny_dataset):
    params, data, reports = tiny_dataset
    m = json.loads((reports / "affordance_maps" / "metrics.json").read_text())
    assert m["n_views"] == 42 * m["n_supports"]
    assert m["contact_visible_rate"] > 0.5
    ids = read_table(data / "mesh_gen" / "supports.parquet", SUPPORTS)["support_id"]
    sid = next(s for s in ids if (data / "affordance_maps" / f"{s}.npz").exists())
    z = read_npz(data / "affordance_maps" / f"{sid}.npz",
                 {"affordance": ("float32", 2), "contact_index": ("int32", 1)})
    assert z["affordance"].shape == (42, 1000)
    # the stored labels follow the formula, recomputed here with loops from the inputs
    p = load_params(params).affordance_maps
    contacts = read_table(data / "contact_sim" / "contacts.parquet", CONTACTS)
    contact = np.asarray(contacts[(contacts["kind"] == "reference_on_support")
                                  & (contacts["support_id"] == sid)]["contact_support"].iloc[0])
    skts = read_table(data / "rrt_skts" / "skts.parquet", SKTS)
    part = np.vstack([hanging_part(np.stack(k), p.hanging_part_m)
                      for k in skts[skts["support_id"] == sid]["keypoints"]])
    cloud = read_npz(data / "render_views" / f"{sid}.npz", RENDER_SPEC)["points"].astype(np.float64)
    for v in (0, 20):
        pts = cloud[v]
        k = min(range(len(pts)), key=lambda i: float(np.sum((pts[i] - contact) ** 2)))
        assert z["contact_index"][v] == k
        m_cp = np.array([np.exp(-np.sum((q - pts[k]) ** 2) / (2 * p.sigma_m**2)) for q in pts])
        expected = p.alpha * m_cp + p.beta * segmentation_map_naive(pts, part, p.sigma_m)
        assert z["affordance"][v] == pytest.approx(expected, abs=1e-6)
    assert 0 <= z["affordance"].min() and z["affordance"].max() <= 1.0 + 1e-6
    # the label is not in the point order: contact points sit anywhere in the cloud
    assert len(np.unique(z["contact_index"])) > 1 or z["contact_index"][0] != 0


def test_clustering_contract_and_determinism(tiny_dataset, tmp_path):
    _, data, reports = tiny_dataset
    m = json.loads((reports / "clustering" / "metrics.json").read_text())
    k = TINY["clustering"]["k"]
    assert m["k"] == k and len(m["cluster_sizes"]) == k and min(m["cluster_sizes"]) > 0
    labels = read_table(data / "clustering" / "labels.parquet", LABELS)
    # one SKT per tiny support: the silhouette is over the training supports' embeddings
    train = labels[labels["split"] == "train"]
    assert m["n_train_skts"] == len(train) == train["n_skts"].sum()
    assert m["silhouette"] == pytest.approx(_silhouette_naive(np.stack(train["embedding"]),
                                                              train["category"].to_numpy()))
    assert set(labels["category"]) <= {0, 1, 2} and labels["is_template"].sum() >= 1
    z = read_npz(data / "clustering" / "templates.npz", {"templates": ("float64", 3)})
    assert z["templates"].shape == (k, 10, 3) and np.allclose(z["templates"][:, 0], 0)
    first, again = _rerun(clustering, tiny_dataset, tmp_path)
    assert (first / "labels.parquet").read_bytes() == (again / "labels.parquet").read_bytes()
    assert (first / "templates.npz").read_bytes() == (again / "templates.npz").read_bytes()


def _silhouette_naive(x, labels):
    """Mean silhouette, textbook definition (a singleton cluster scores 0)."""
    scores = []
    for i in range(len(x)):
        dist = {c: [float(np.linalg.norm(x[i] - x[j])) for j in range(len(x))
                    if labels[j] == c and j != i] for c in set(labels.tolist())}
        own = dist.pop(labels[i])
        if not own or not dist:
            scores.append(0.0)
            continue
        a, b = np.mean(own), min(np.mean(d) for d in dist.values())
        scores.append((b - a) / max(a, b))
    return float(np.mean(scores))


def _first_hit(origin, dirs, tris):
    """Distance along each unit ray ``dirs (R, 3)`` from ``origin`` to the nearest triangle
    of ``tris (F, 3, 3)`` (Möller–Trumbore, numpy; inf for a miss)."""
    e1, e2 = tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0]
    p = np.cross(dirs[:, None], e2[None])  # (R, F, 3)
    det = np.einsum("rfk,fk->rf", p, e1)
    ok = np.abs(det) > 1e-15
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    s = origin - tris[:, 0]  # (F, 3)
    u = np.einsum("rfk,fk->rf", p, s) * inv
    q = np.cross(s, e1)  # (F, 3)
    w = np.einsum("rk,fk->rf", dirs, q) * inv
    t = np.einsum("fk,fk->f", e2, q)[None] * inv
    hit = ok & (u >= -1e-9) & (w >= -1e-9) & (u + w <= 1 + 1e-9) & (t > 1e-9)
    return np.where(hit, t, np.inf).min(axis=1)
