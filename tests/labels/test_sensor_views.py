"""Depth-camera views for training (``render_views.sensor_views_severity`` > 0): rendered for
the training and validation supports only, labelled by ``affordance_maps``, and learned from
by the models ``train_baselines.views`` names — while Table I's views stay byte-identical."""

import copy
import json

import numpy as np
import pytest
import yaml

from skt_lib.errors import DataError
from skt_lib.io import read_npz, read_table
from skt_lib.config.train_baselines import VIEW_SETS
from skt_lib.learning.data import AFF_SPEC, VIEW_DIRS, load_training_set
from skt_lib.perception.render import DepthRenderer
from skt_lib.geometry.export import read_obj
from skt_lib.perception.views import RENDER_SPEC, SENSOR_DIR
from skt_lib.schemas import SUPPORTS
from stages import affordance_maps, render_views, train_baselines
from tests.conftest import TINY

pytestmark = pytest.mark.slow


def _params(tmp_path, name, **render):
    data = copy.deepcopy(TINY)
    data["render_views"].update({"n_azimuth": 3, "n_elevation": 2, **render})
    data["train_baselines"].update({"models": ["vatmart", "skt_flow"],
                                    "views": {"skt_flow": "both"}})
    path = tmp_path / f"{name}.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def _root(tiny_data, tmp_path, name):
    """A data root with the tiny dataset's upstream stages and fresh views and maps."""
    root = tmp_path / name
    root.mkdir()
    for stage in ("mesh_gen", "contact_sim", "rotation_extraction", "rrt_skts", "clustering"):
        (root / stage).symlink_to(tiny_data / stage)
    return root


def _run(stage, params, root, tmp_path):
    name = stage.__name__.rsplit(".", 1)[-1]
    rep = tmp_path / f"rep_{root.name}" / name
    assert stage.main(["--params", str(params), "--data-root", str(root), "--data-dir",
                       str(root / name), "--reports-dir", str(rep),
                       "--log-dir", str(tmp_path / "logs")]) == 0
    return json.loads((rep / "metrics.json").read_text())


def test_sensor_views_are_rendered_labelled_and_learned_from(tiny_dataset, tmp_path, monkeypatch):
    _, tiny_data, _ = tiny_dataset
    supports = read_table(tiny_data / "mesh_gen" / "supports.parquet", SUPPORTS)
    fit = set(supports["support_id"][supports["split"].isin(["train", "val"])])
    clean_root = _root(tiny_data, tmp_path, "clean")
    _run(render_views, _params(tmp_path, "clean"), clean_root, tmp_path)
    root = _root(tiny_data, tmp_path, "sensor")
    params = _params(tmp_path, "sensor", sensor_views_severity=1.0)
    m = _run(render_views, params, root, tmp_path)

    # Table I's views are the same bytes with or without the depth-camera ones
    for sid in supports["support_id"]:
        assert ((root / "render_views" / f"{sid}.npz").read_bytes()
                == (clean_root / "render_views" / f"{sid}.npz").read_bytes())
    sensor = root / "render_views" / SENSOR_DIR
    assert {p.stem for p in sensor.glob("*.npz")} == fit  # no test support's
    assert m["sensor_views"]["n_supports"] == m["sensor_views"]["n_rendered"] == len(fit)
    assert m["sensor_views"]["severity"] == 1.0
    mesh_of = dict(zip(supports["support_id"], supports["mesh_path"]))
    for sid in sorted(fit)[:2]:
        views = read_npz(sensor / f"{sid}.npz", RENDER_SPEC)["points"]
        clean = read_npz(root / "render_views" / f"{sid}.npz", RENDER_SPEC)["points"]
        assert views.shape == clean.shape == (6, 1000, 3) and not np.array_equal(views, clean)
        (mesh,) = read_obj(tiny_data / "mesh_gen" / mesh_of[sid])
        d = DepthRenderer(mesh, 40.0).distance(views.reshape(-1, 3).astype(np.float64))
        assert np.median(d) < 0.0015  # the hook seen by a noisy camera, not the wall

    a = _run(affordance_maps, params, root, tmp_path)
    labelled = {p.stem for p in (root / "affordance_maps" / SENSOR_DIR).glob("*.npz")}
    assert labelled and labelled <= fit
    assert a["sensor_views"]["n_views"] == 6 * len(labelled)
    assert a["n_views"] == 6 * a["n_supports"]
    assert 0.5 < a["sensor_views"]["contact_visible_rate"] <= 1.0

    assert set(VIEW_DIRS) == set(VIEW_SETS)  # every value the params accept loads
    both, sens, clean = (load_training_set(root, v) for v in ("both", "sensor", "clean"))
    for b, s, c in zip(both.train + both.val, sens.train + sens.val, clean.train + clean.val):
        assert b.support_id == s.support_id == c.support_id
        np.testing.assert_array_equal(b.points, np.concatenate([c.points, s.points]))
        np.testing.assert_array_equal(b.affordance, np.concatenate([c.affordance, s.affordance]))
        np.testing.assert_array_equal(
            s.affordance, read_npz(root / "affordance_maps" / SENSOR_DIR / f"{s.support_id}.npz",
                                   AFF_SPEC)["affordance"])
    with pytest.raises(DataError, match="sensor_views_severity"):
        load_training_set(clean_root, "sensor")

    seen = {}

    class Saved:
        def save(self, path):
            pass

    def fake_train(name, cfg, templates, train, val, st, seed, n_prop, pb, on_epoch):
        seen[name] = (train[0].points.shape[0], val[0].points.shape[0])
        on_epoch(0, {"val_traj_l2_mm": 1.0})
        return Saved(), {"val_traj_l2_mm": 1.0}

    monkeypatch.setattr(train_baselines, "train_baseline", fake_train)
    _run(train_baselines, params, root, tmp_path)
    assert seen == {"vatmart": (6, 6), "skt_flow": (12, 12)}
    report = (tmp_path / "rep_sensor" / "train_baselines" / "report.md").read_text()
    assert "| skt_flow | both |" in report and "| vatmart | clean |" in report
