import numpy as np
import pytest
import torch

from skt_lib.learning.data import SupportData
from skt_lib.learning.predictor import SktPredictor
from skt_lib.learning.sctdn import Sctdn, SctdnConfig, sctdn_loss
from skt_lib.learning.train import make_batch


def _supports(n=4, T=8):
    rng = np.random.default_rng(0)
    out = []
    for i in range(n):
        pts = rng.normal(size=(2, 256, 3)).astype(np.float32) * 0.05
        contact = pts[0, 0].astype(np.float64)
        skt = contact + np.outer(np.linspace(0, 1, T), [0.1, 0.02 * i, 0.05])
        aff = np.exp(-np.linalg.norm(pts - contact, axis=-1) ** 2 / 2e-4).astype(np.float32)
        out.append(SupportData(f"s{i}", "train", i % 2, pts, aff, skt[None], contact))
    return out


def test_overfits_one_batch():
    sup = _supports()
    cfg = SctdnConfig(k=2, T=8, n_points=256)
    b = make_batch([(s, 0) for s in sup])
    losses = []
    with torch.random.fork_rng():  # dropout draws from torch's RNG: isolate and seed it
        torch.manual_seed(0)
        model = Sctdn(cfg, torch.zeros(2, 8, 3))
        opt = torch.optim.Adam(model.parameters(), 3e-3)
        for _ in range(250):
            out = model(b["xyz"], b["scale"], b["family"], b["contact"])
            loss, _ = sctdn_loss(out, b["gt"], b["valid"], b["aff"], b["family"])
            opt.zero_grad()
            loss.backward()
            opt.step()
            losses.append(float(loss))
    assert losses[-1] < losses[0] / 10


def test_starts_at_the_template_and_rejects_bad_templates():
    cfg = SctdnConfig(k=2, T=8, n_points=256)
    model = Sctdn(cfg, torch.randn(2, 8, 3) * 0.01)
    b = make_batch([(s, 0) for s in _supports()])
    out = model(b["xyz"], b["scale"], b["family"], b["contact"])
    assert torch.allclose(out["trajectory"], out["aligned"])  # zero-initialised deformation
    with pytest.raises(ValueError, match="templates"):
        Sctdn(cfg, torch.zeros(3, 8, 3))


def test_predictor_roundtrip_and_input_checks(tmp_path):
    cfg = SctdnConfig(k=2, T=8, n_points=256)
    with torch.random.fork_rng():
        torch.manual_seed(1)
        pred = SktPredictor(Sctdn(cfg, torch.randn(2, 8, 3) * 0.01))
    pred.save(tmp_path)
    back = SktPredictor.load(tmp_path)
    pts = _supports()[0].points[0]
    a, b = pred.predict(pts), back.predict(pts)
    assert np.allclose(a.positions, b.positions) and a.frames.shape == (8, 4, 4)
    with pytest.raises(ValueError, match="NaN"):
        pred.predict(np.full((256, 3), np.nan))
    with pytest.raises(ValueError, match="at least 256"):
        pred.predict(pts[:10])
    (tmp_path / "sctdn.pt").write_bytes(b"garbage")
    from skt_lib.errors import DataError
    with pytest.raises(DataError, match="cannot load"):
        SktPredictor.load(tmp_path)
