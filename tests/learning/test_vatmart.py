"""VAT-Mart baselines and the SCTDN contact-point ablation: shapes, determinism, learning."""

from types import SimpleNamespace

import numpy as np
import pytest
import torch

from skt_lib.errors import DataError
from skt_lib.eval.methods import make_method
from skt_lib.learning.sctdn import (
    Sctdn,
    SctdnConfig,
    backbone_features,
    feature_at,
    masked_max_pool,
)
from skt_lib.learning.train import make_batch
from skt_lib.learning.vatmart import (
    VatMart,
    VatMartConfig,
    VatMartPredictor,
    hat_basis,
    pick_targets,
    vatmart_loss,
)
from tests.learning.test_sctdn import _supports

T = 8


def _model(condition="contact_point", kl=0.1, seed=0, latent=16):
    cfg = VatMartConfig(T=T, condition=condition, kl_weight=kl, n_points=256, latent=latent,
                        hidden=64, n_control=4)
    with torch.random.fork_rng():
        torch.manual_seed(seed)
        return VatMart(cfg)


@pytest.mark.parametrize("condition", ["contact_point", "shape"])
def test_proposals_have_the_contract_shapes_and_start_at_the_contact(condition):
    pred = VatMartPredictor(_model(condition))
    pts = _supports()[0].points[0].astype(np.float64)
    skts = pred.propose(pts, np.random.default_rng(3), n=10)
    assert len(skts) == 10
    for s in skts:
        assert s.positions.shape == (T, 3) and s.frames.shape == (T, 4, 4)
        assert np.allclose(s.frames[:, :3, 3], s.positions)
        assert s.affordance.shape == (256,)
        assert np.array_equal(s.contact, skts[0].contact)  # one contact point per cloud
        assert np.array_equal(s.contact, pts[int(s.affordance.argmax())])
    # the latent changes the proposal: ten different trajectories
    flat = np.stack([s.positions.ravel() for s in skts])
    assert len(np.unique(flat.round(9), axis=0)) == 10
    with pytest.raises(ValueError, match="at least 256"):
        pred.propose(pts[:100], np.random.default_rng(0), n=2)
    with pytest.raises(ValueError, match="n: need at least one"):
        pred.propose(pts, np.random.default_rng(0), n=0)


def test_same_generator_same_skts_and_the_method_repeats_itself():
    pred = VatMartPredictor(_model())
    pts = _supports()[0].points[0].astype(np.float64)
    a = pred.propose(pts, np.random.default_rng(7), n=4)
    b = pred.propose(pts, np.random.default_rng(7), n=4)
    c = pred.propose(pts, np.random.default_rng(8), n=4)
    assert all(np.array_equal(x.positions, y.positions) for x, y in zip(a, b))
    assert not np.allclose(a[0].positions, c[0].positions)
    gt = np.zeros((T, 3))
    method = make_method("vatmart", pred, gt, np.array([0.1, 0, 0]), rng=np.random.default_rng(7),
                         n_proposals=4)
    first, again = method.propose(pts), method.propose(pts)  # no hidden generator state
    assert all(np.array_equal(x.positions, y.positions) for x, y in zip(first, again))
    assert all(np.array_equal(x.positions, y.positions) for x, y in zip(first, a))
    assert np.array_equal(method.predict(pts).positions, a[0].positions)  # single = first
    with pytest.raises(ValueError, match="generator"):
        make_method("vatmart", pred, gt, np.array([0.1, 0, 0]))


def test_checkpoint_roundtrip_and_corrupt_file(tmp_path):
    pred = VatMartPredictor(_model("shape", kl=0.01))
    pred.save(tmp_path)
    back = VatMartPredictor.load(tmp_path)
    assert back.cfg == pred.cfg
    pts = _supports()[1].points[0].astype(np.float64)
    a = pred.propose(pts, np.random.default_rng(0), 3)
    b = back.propose(pts, np.random.default_rng(0), 3)
    assert all(np.array_equal(x.positions, y.positions) for x, y in zip(a, b))
    (tmp_path / "vatmart.pt").write_bytes(b"not a checkpoint")
    with pytest.raises(DataError, match="cannot load the VAT-Mart checkpoint"):
        VatMartPredictor.load(tmp_path)


def test_hat_basis_interpolates_control_points_piecewise_linearly():
    b = hat_basis(9, 3).double()
    assert b.shape == (9, 3) and torch.allclose(b.sum(1), torch.ones(9, dtype=torch.float64))
    ctrl = torch.tensor([[0.0, 0, 0], [1.0, 2, 0], [1.0, 2, 4]], dtype=torch.float64)
    traj = b @ ctrl
    assert torch.equal(traj[0], ctrl[0]) and torch.equal(traj[4], ctrl[1])
    assert torch.equal(traj[8], ctrl[2])
    assert torch.allclose(traj[2], (ctrl[0] + ctrl[1]) / 2)
    # piecewise linear: constant direction within each half, so the SKT rule's frames turn
    # only at the control point
    seg = torch.diff(traj, dim=0)
    assert torch.allclose(seg[:4], seg[0].expand(4, 3))
    assert torch.allclose(seg[4:], seg[4].expand(4, 3))
    with pytest.raises(ValueError, match="n_control"):
        VatMartConfig(T=8, condition="shape", kl_weight=0.1, n_control=9)


def test_config_rejects_unknown_condition():
    with pytest.raises(ValueError, match="condition"):
        VatMartConfig(T=T, condition="global", kl_weight=0.1)
    with pytest.raises(ValueError, match="condition"):
        SctdnConfig(k=2, T=T, n_points=256, condition="global")
    # checkpoints written before the ablation existed load as full SCTDN
    old = SctdnConfig(k=2, T=T, n_points=256).to_json().replace('"condition": "shape",', "")
    assert SctdnConfig.from_json(old).condition == "shape"


def test_reconstructs_a_batch_it_overfits():
    sup = _supports()
    b = make_batch([(s, 0) for s in sup])
    parts = []
    with torch.random.fork_rng():
        torch.manual_seed(0)
        model = _model(kl=0.0)
        opt = torch.optim.Adam(model.parameters(), 3e-3)
        for _ in range(80):
            target = pick_targets(b["gt"], b["valid"])
            out = model(b["xyz"], target, b["contact"])
            loss, part = vatmart_loss(out, target, b["aff"], b["contact_target"], 0.0)
            opt.zero_grad()
            loss.backward()
            opt.step()
            parts.append(part)
    assert parts[-1]["traj"] < parts[0]["traj"] / 10
    assert parts[-1]["aff"] < parts[0]["aff"]


def test_pick_targets_draws_only_valid_skts_and_all_of_them():
    gt = torch.arange(2 * 3 * T * 3, dtype=torch.float32).view(2, 3, T, 3)
    valid = torch.tensor([[True, False, True], [False, True, False]])
    seen = set()
    with torch.random.fork_rng():
        torch.manual_seed(0)
        for _ in range(60):
            picked = pick_targets(gt, valid)
            for b in range(2):
                (g,) = [g for g in range(3) if torch.equal(picked[b], gt[b, g])]
                assert valid[b, g]
                seen.add((b, g))
    assert seen == {(0, 0), (0, 2), (1, 1)}


def test_feature_at_takes_the_nearest_points_column_and_the_ablation_uses_it():
    feats = torch.arange(2 * 4 * 5, dtype=torch.float32).view(2, 4, 5)
    xyz = torch.zeros(2, 5, 3)
    xyz[0, 3] = torch.tensor([1.0, 0, 0])
    xyz[1, 1] = torch.tensor([0, 1.0, 0])
    got = feature_at(feats, xyz, torch.tensor([[0.9, 0, 0], [0, 0.8, 0]]))
    assert torch.equal(got, torch.stack([feats[0, :, 3], feats[1, :, 1]]))
    # each variant's deformation is conditioned on its own feature, recomputed here by hand
    sup = _supports()
    b = make_batch([(s, 0) for s in sup])
    contact = b["xyz"][:, 17]
    for condition in ("contact_point", "shape"):
        cfg = SctdnConfig(k=2, T=T, n_points=256, condition=condition)
        with torch.random.fork_rng():
            torch.manual_seed(0)
            model = Sctdn(cfg, torch.randn(2, T, 3) * 0.01).eval()
            torch.nn.init.normal_(model.offset.weight, std=0.1)
        with torch.no_grad():
            out = model(b["xyz"], b["scale"], b["family"], contact)
            _, feats = backbone_features(model, b["xyz"])
            cond = {"contact_point": feature_at(feats, b["xyz"], contact),
                    "shape": masked_max_pool(feats, out["affordance"], cfg.aff_threshold)}
            for name, c in cond.items():
                x = torch.cat([model.wp_mlp(out["aligned"]),
                               c[:, None].expand(-1, T, -1)], -1)
                traj = out["aligned"] + model.offset(model.lstm(x)[0])
                assert torch.allclose(traj, out["trajectory"], atol=1e-6) == (name == condition)


def test_training_is_a_function_of_the_seed():
    from dataclasses import replace

    from skt_lib.learning.train import TrainSettings
    from skt_lib.learning.train_baselines import train_vatmart, vatmart_config

    sup = _supports()
    val = [replace(s, split="val") for s in sup[:2]]
    st = TrainSettings(epochs=1, views_per_epoch=1, batch_size=2, lr=1e-3, lr_final_ratio=0.1,
                       weight_decay=0.0, val_views=(0,), contact_weight=0.1, threads=1)
    base = SctdnConfig(k=2, T=T, n_points=256)
    cfg = vatmart_config("vatmart_mod", base, SimpleNamespace(
        latent_dim=8, hidden=32, n_control_points=3, vatmart_kl_weight=0.1,
        vatmart_mod_kl_weight=0.01))
    assert (cfg.condition, cfg.kl_weight, cfg.latent, cfg.n_control) == ("shape", 0.01, 8, 3)
    runs = [train_vatmart(cfg, sup, val, st, seed, 3)[0].state_dict() for seed in (5, 5, 6)]
    same = all(torch.equal(runs[0][k], runs[1][k]) for k in runs[0])
    other = all(torch.equal(runs[0][k], runs[2][k]) for k in runs[0])
    assert same and not other
    with pytest.raises(ValueError, match="name"):
        vatmart_config("vatmart_xl", base, None)
