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
