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
        lo, hi = m[f"{key}_ci95"]  # the best epoch's figure lies in its interval
        assert lo <= m[key] <= hi
    assert (reports / "train" / "live" / "plots" / "metrics").is_dir()
    pred = SktPredictor.load(data / "train")
    cloud = read_npz(next((data / "render_views").glob("*.npz")), RENDER_SPEC)["points"][3]
    skt = pred.predict(cloud)
    assert skt.positions.shape == (pred.cfg.T, 3) and np.isfinite(skt.positions).all()
    r = skt.frames[:, :3, :3]
    assert np.allclose(np.einsum("tji,tjk->tik", r, r), np.eye(3), atol=1e-9)
    # the predicted end waypoint sits near the cloud (the hang is on the support)
    assert np.linalg.norm(cloud - skt.positions[0], axis=1).min() < 0.05


@pytest.mark.parametrize("name", ["train", "train_baselines"])
def test_training_refuses_to_select_on_training_supports(name, monkeypatch, tmp_path):
    """No validation split → a clear DataError, never figures labelled val_* from train."""
    import importlib
    from types import SimpleNamespace

    from skt_lib.errors import DataError
    from skt_lib.learning import data
    from skt_lib.learning.data import SupportData

    stage = importlib.import_module(f"stages.{name}")
    sup = [SupportData(f"s{i}", "train", 0, np.zeros((2, 16, 3), np.float32),
                       np.zeros((2, 16), np.float32), np.zeros((1, 10, 3)), np.zeros(3),
                       np.ones((2, 16), np.float32), np.ones(2, bool))
           for i in range(3)]
    monkeypatch.setattr(stage, "load_sections", lambda *_, **__: SimpleNamespace(
        train=SimpleNamespace(), train_baselines=SimpleNamespace(models=("skt_flow",), views={}),
        common=SimpleNamespace(seed=0)))
    monkeypatch.setattr(data, "read_npz", lambda *a: {"templates": np.zeros((1, 10, 3)),
                                                      "T": 10, "k": 1})
    monkeypatch.setattr(data, "load_supports", lambda *a: sup)
    trainer = "train_sctdn" if name == "train" else "train_baseline"
    monkeypatch.setattr(stage, trainer, lambda *a: pytest.fail("trained without val"))
    with pytest.raises(DataError, match="0 validation supports.*n_val_per_level"):
        stage.main(["--data-root", str(tmp_path), "--data-dir", str(tmp_path / "o"),
                    "--reports-dir", str(tmp_path / "r")])
    assert not (tmp_path / "o").exists() and not (tmp_path / "r").exists()


def test_train_report_units():
    from stages.train import _unit

    assert _unit("val_traj_l2_mm") == "mm" and _unit("val_template_only_l2_mm") == "mm"
    assert "normalised" in _unit("train_traj") and "normalised" in _unit("train_loss")


def _diagnostics_tool():
    import importlib.util
    from pathlib import Path

    spec = importlib.util.spec_from_file_location(
        "train_diagnostics", Path(__file__).parents[2] / "tools" / "train_diagnostics.py")
    tool = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(tool)
    return tool


def test_contact_misses_splits_along_and_across_the_arm():
    """Each view's pick is a point at a known offset from the contact: along the arm, across
    it, within 1 cm; a view that does not show the contact is not counted."""
    import torch

    from skt_lib.learning.data import SupportData

    tool = _diagnostics_tool()
    contact = np.array([0.05, 0.0, 0.01])
    offsets = [[0.03, 0.0, 0.0], [-0.025, 0.004, 0.0], [0.0, 0.0, 0.02], [0.005, 0.0, 0.0],
               [0.0, 0.0, 0.0]]  # along, along, across, within; the last view hides the contact
    pts = np.random.default_rng(0).uniform(-0.2, 0.2, (5, 32, 3)).astype(np.float32)
    for v, off in enumerate(offsets):
        pts[v, 7] = contact + off
    aff = np.zeros((5, 32), np.float32)
    sup = SupportData("s0", "val", 0, pts, aff, np.zeros((1, 10, 3)), contact, aff,
                      np.array([True, True, True, True, False]), "hard")

    class Picks:  # the affordance peaks at point 7 of every view
        def eval(self):
            return self

        def __call__(self, xyz, scale):
            a = torch.zeros(xyz.shape[:2])
            a[:, 7] = 1.0
            return {"affordance": a}

    r = tool.contact_misses(Picks(), [sup], [0, 1, 2, 3, 4], {"s0": np.array([1.0, 0.0, 0.0])})
    assert r["hard"] == r["all"] == {"visible": 4, "within_1cm": 1, "misses_along_arm": 2,
                                     "within_1cm_across_arm": 3}
    assert set(r) == {"hard", "all"}


def test_per_level_measures_each_level_against_known_predictions():
    """A stand-in model whose predictions are the ground truth moved by known amounts: the
    SKT, hanging-end and ξ_0 errors, the confusion and the contact come out exactly, per
    level and over all; with the true family and contact given (teacher forcing) it returns
    the ground truth itself."""
    import torch

    from skt_lib.learning.data import SupportData

    tool = _diagnostics_tool()
    T, k = 12, 3
    rng = np.random.default_rng(0)
    pts = rng.uniform(-0.1, 0.1, (2, 32, 3)).astype(np.float32)
    gt = np.cumsum(rng.normal(0.0, 0.01, (1, T, 3)), axis=1)
    aff = np.zeros((2, 32), np.float32)
    easy = SupportData("e", "val", 0, pts, aff, gt, pts[0, 3].astype(np.float64), aff,
                       np.array([True, False]), "easy")  # the second view hides the contact
    hard = SupportData("h", "val", 2, pts, aff, gt, pts[0, 3].astype(np.float64) + [0.0, 0.02, 0.0],
                       aff, np.array([True, True]), "hard")
    shift = {"e": 0.004, "h": 0.01}  # metres along x over the hanging end, three times that beyond

    class Known:
        def eval(self):
            return self

        def __call__(self, xyz, scale, family=None, contact=None):
            n = len(xyz)
            sid = "e" if self.level == "easy" else "h"
            c, sc = self.centroid[:, None], self.scale[:, None, None]  # per view
            truth = torch.as_tensor((gt[0][None] - c) / sc, dtype=torch.float32)
            move = torch.zeros(n, T, 3)
            if family is None:
                step = torch.as_tensor(shift[sid] / sc[..., 0], dtype=torch.float32)
                move[:, :tool.HANG_END, 0] = step  # the hanging end: the shift …
                move[:, tool.HANG_END:, 0] = 3 * step  # … the rest of the way: three times it
            logits = torch.zeros(n, k)
            logits[:, 1 if sid == "h" else 0] = 1.0  # the hard support taken for family 1
            a = torch.zeros(n, xyz.shape[1])
            a[:, 3] = 1.0  # picks point 3: the easy support's contact, 2 cm off the hard one's
            return {"trajectory": truth + move, "logits": logits, "affordance": a}

    model = Known()
    real = tool.make_batch

    def batch(items):
        b = real(items)
        s = items[0][0]
        model.level, model.scale, model.centroid = s.level, b["scale"].double().numpy(), b["centroid"].double().numpy()
        return b

    tool.make_batch = batch
    try:
        r = tool.per_level(model, [easy, hard], [0, 1], k)
    finally:
        tool.make_batch = real
    assert set(r) == {"easy", "hard", "all"}
    whole = (tool.HANG_END + 3 * (T - tool.HANG_END)) / T  # the SKT's mean, in shifts
    for lv, mm in (("easy", 4.0), ("hard", 10.0)):
        for key, want in (("traj_mm", mm * whole), ("hang_end_mm", mm), ("xi0_mm", mm)):
            assert r[lv][key] == pytest.approx(want, abs=1e-3), (lv, key)
        assert r[lv]["forced_traj_mm"] == pytest.approx(0.0, abs=1e-3)
        assert r[lv]["n_views"] == 2
    assert r["all"]["traj_mm"] == pytest.approx(7.0 * whole, abs=1e-3)
    assert r["easy"]["cls_acc"] == 1.0 and r["hard"]["cls_acc"] == 0.0
    assert r["hard"]["confusion"] == [[0, 0, 0], [0, 0, 0], [0, 2, 0]]
    assert r["all"]["confusion"] == [[2, 0, 0], [0, 0, 0], [0, 2, 0]]
    assert (r["easy"]["contact_within_1cm"], r["easy"]["n_contact_visible"]) == (1.0, 1)
    assert (r["hard"]["contact_within_1cm"], r["hard"]["n_contact_visible"]) == (0.0, 2)


def test_train_diagnostics_tool_writes_its_tables(tiny_dataset, tmp_path):
    """tools/train_diagnostics.py on the tiny dataset: every section present, finite, the
    learning curve on ¼, ½ and all training supports, and the overfit run lowers the error."""
    tool = _diagnostics_tool()
    params, data, _ = tiny_dataset
    assert tool.main(["--params", str(params), "--data-root", str(data), "--out", str(tmp_path),
                      "--epochs", "1", "--steps", "30"]) == 0
    d = json.loads((tmp_path / "diagnostics.json").read_text())
    o = d["overfit_one_batch"]
    assert o["traj_last_mm"] < o["traj_first_mm"]
    sizes = [r["n_train_supports"] for r in d["learning_curve"]]
    assert len(sizes) == 3 and sizes == sorted(sizes)
    for r in d["learning_curve"] + [d["contact_weight_0"]]:
        assert np.isfinite(r["val_traj_l2_mm"]) and r["epochs"] == 1
    assert set(d["committed_model"]) == {"train", "val"}
    e = d["error_sources"]
    assert set(e) == {"predicted", "true_family", "true_family_and_contact"}
    assert all(np.isfinite(v["traj_mm"]) and np.isfinite(v["xi0_mm"]) for v in e.values())
    assert d["contact_misses"]["all"]["visible"] == sum(
        r["visible"] for lv, r in d["contact_misses"].items() if lv != "all")
    pl = d["per_level"]
    assert pl["all"]["n_views"] == sum(r["n_views"] for lv, r in pl.items() if lv != "all")
    assert sum(map(sum, pl["all"]["confusion"])) == pl["all"]["n_views"]
    md = (tmp_path / "diagnostics.md").read_text()
    assert "Learning curve" in md and "Where the contact misses" in md and "**Per level**" in md


def test_train_twice_gives_the_same_checkpoint_bytes(tiny_dataset, tmp_path):
    """The stage run again on the same inputs writes the same sctdn.pt bytes and metrics
    (no temp-file names inside the zip, fixed threads, deterministic kernels)."""
    from stages import train as stage

    params, data, reports = tiny_dataset
    first = (data / "train" / "sctdn.pt").read_bytes()
    assert stage.main(["--params", str(params), "--data-root", str(data),
                       "--data-dir", str(tmp_path / "train"),
                       "--reports-dir", str(tmp_path / "reports")]) == 0
    assert (tmp_path / "train" / "sctdn.pt").read_bytes() == first
    assert (tmp_path / "reports" / "metrics.json").read_text() == \
        (reports / "train" / "metrics.json").read_text()
    m = json.loads((tmp_path / "reports" / "metrics.json").read_text())
    assert not [k for k in m if k.endswith(("_ms", "_ms_median", "_s", "_s_median"))], \
        "wall-clock figures belong in the bench, not in metrics.json"
