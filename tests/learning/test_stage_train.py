"""train on the tiny dataset: contract, a loadable checkpoint, a usable predictor."""

import json

import numpy as np
import pytest

from skt_lib.io import read_npz
from skt_lib.learning.predictor import SktPredictor
from skt_lib.perception.views import RENDER_SPEC

pytestmark = pytest.mark.slow


def test_train_contract_and_predictor(tiny_dataset):
    _, data, reports = tiny_dataset
    m = json.loads((reports / "train" / "metrics.json").read_text())
    for key in ("val_traj_l2_mm", "val_template_only_l2_mm", "val_affordance_mse", "val_cls_acc"):
        assert np.isfinite(m[key])
    assert (reports / "train" / "live" / "plots" / "metrics").is_dir()
    pred = SktPredictor.load(data / "train")
    cloud = read_npz(next((data / "render_views").glob("*.npz")), RENDER_SPEC)["points"][3]
    skt = pred.predict(cloud)
    assert skt.positions.shape == (pred.cfg.T, 3) and np.isfinite(skt.positions).all()
    r = skt.frames[:, :3, :3]
    assert np.allclose(np.einsum("tji,tjk->tik", r, r), np.eye(3), atol=1e-9)
    # the predicted end waypoint sits near the cloud (the hang is on the support)
    assert np.linalg.norm(cloud - skt.positions[0], axis=1).min() < 0.05


def test_train_refuses_to_select_on_training_supports(monkeypatch, tmp_path):
    """No validation split → a clear DataError, never figures labelled val_* from train."""
    from types import SimpleNamespace

    from skt_lib.errors import DataError
    from skt_lib.learning.data import SupportData
    from stages import train as stage

    sup = [SupportData(f"s{i}", "train", 0, np.zeros((2, 16, 3), np.float32),
                       np.zeros((2, 16), np.float32), np.zeros((1, 10, 3)), np.zeros(3))
           for i in range(3)]
    monkeypatch.setattr(stage, "load_params", lambda _: SimpleNamespace(
        train=SimpleNamespace(), common=SimpleNamespace(seed=0)))
    monkeypatch.setattr(stage, "read_npz", lambda *a: {"templates": np.zeros((1, 10, 3)),
                                                        "T": 10, "k": 1})
    monkeypatch.setattr(stage, "load_supports", lambda *a: sup)
    monkeypatch.setattr(stage, "train_sctdn", lambda *a: pytest.fail("trained without val"))
    with pytest.raises(DataError, match="0 validation supports.*n_val_per_level"):
        stage.main(["--data-root", str(tmp_path), "--data-dir", str(tmp_path / "o"),
                    "--reports-dir", str(tmp_path / "r")])


def test_train_report_units():
    from stages.train import _unit

    assert _unit("val_traj_l2_mm") == "mm" and _unit("val_template_only_l2_mm") == "mm"
    assert "normalised" in _unit("train_traj") and "normalised" in _unit("train_loss")
