import json

import numpy as np
import pytest
import torch

from skt_lib.learning.data import SupportData, normalise
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
        out.append(SupportData(f"s{i}", "train", i % 2, pts, aff, skt[None], contact, aff,
                               np.ones(2, bool)))
    return out


def test_overfits_one_batch():
    sup = _supports()
    cfg = SctdnConfig(k=2, T=8, n_points=256)
    b = make_batch([(s, 0) for s in sup])
    parts = []
    with torch.random.fork_rng():  # dropout draws from torch's RNG: isolate and seed it
        torch.manual_seed(0)
        model = Sctdn(cfg, torch.zeros(2, 8, 3))
        opt = torch.optim.Adam(model.parameters(), 3e-3)
        for _ in range(250):
            out = model(b["xyz"], b["scale"], b["family"], b["contact"])
            loss, part = sctdn_loss(out, b["gt"], b["valid"], b["aff"], b["family"], b["contact_target"])
            opt.zero_grad()
            loss.backward()
            opt.step()
            parts.append(part)
    # the trajectory error goes (nearly) to zero; the contact cross-entropy more than halves
    # its distance to its floor, the entropy of the target distribution
    assert parts[-1]["traj"] < parts[0]["traj"] / 10
    t = b["contact_target"]
    entropy = float(-(t * torch.log(t.clamp_min(1e-30))).sum(-1).mean())
    assert parts[-1]["contact"] - entropy < (parts[0]["contact"] - entropy) / 2
    assert parts[-1]["cls"] < 0.05


def test_starts_at_the_template_and_rejects_bad_templates():
    cfg = SctdnConfig(k=2, T=8, n_points=256)
    model = Sctdn(cfg, torch.randn(2, 8, 3) * 0.01)
    b = make_batch([(s, 0) for s in _supports()])
    out = model(b["xyz"], b["scale"], b["family"], b["contact"])
    assert torch.allclose(out["trajectory"], out["aligned"])  # zero-initialised deformation
    with pytest.raises(ValueError, match="templates"):
        Sctdn(cfg, torch.zeros(3, 8, 3))


def test_the_hang_taper_keeps_the_hang_at_the_contact_and_deforms_beyond_it():
    b = make_batch([(s, 0) for s in _supports()])
    outs = {}
    for n in (0, 3):
        torch.manual_seed(0)
        model = Sctdn(SctdnConfig(k=2, T=8, n_points=256, hang_taper=n), torch.zeros(2, 8, 3))
        torch.nn.init.normal_(model.offset.bias)  # a deformation that is not zero
        outs[n] = model.eval()(b["xyz"], b["scale"], b["family"], b["contact"])
    free, tapered = (outs[n]["trajectory"] - outs[n]["aligned"] for n in (0, 3))
    assert (free.norm(dim=-1) > 0.1).all()  # untapered: every waypoint moves, ξ_0 too
    assert torch.equal(tapered[:, 0], torch.zeros_like(tapered[:, 0]))  # ξ_0: at the contact
    assert torch.allclose(tapered[:, 1:3], free[:, 1:3] * torch.tensor([1 / 3, 2 / 3])[:, None])
    assert torch.equal(tapered[:, 3:], free[:, 3:])  # past the taper: the same deformation
    with pytest.raises(ValueError, match="hang_taper"):
        SctdnConfig(k=2, T=8, hang_taper=8)


def _lifted(sup: SupportData, offsets_m) -> SupportData:
    """``sup`` with one SKT per row of ``offsets_m (G, 3)``: its own SKT moved so that ξ_0 is
    that far from the contact."""
    skts = np.stack([sup.skts[0] - sup.skts[0, 0] + sup.contact + o for o in np.asarray(offsets_m)])
    return SupportData(**{**sup.__dict__, "skts": skts})


def test_release_lift_is_the_mean_height_of_xi0_over_the_contact_each_support_once():
    from skt_lib.learning.train import release_lift

    s0, s1 = _supports(2)
    # s0: ξ_0 1 and 3 mm above its contact (mean 2); s1: 6 mm; sideways offsets do not count
    sup = [_lifted(s0, [[0.004, -0.003, 0.001], [0.0, 0.002, 0.003]]), _lifted(s1, [[0.0, 0.01, 0.006]])]
    assert release_lift(sup) == pytest.approx(0.004)  # per support: (2 + 6) / 2, not 10 / 3
    with pytest.raises(ValueError, match="supports"):
        release_lift([])


def test_the_template_goes_release_lift_above_the_contact_and_training_sets_it():
    from skt_lib.learning.train import TrainSettings, train_sctdn

    sup = _supports()
    b = make_batch([(s, 0) for s in sup])
    templates = torch.randn(2, 8, 3) * 0.01
    flat, lifted = (Sctdn(SctdnConfig(k=2, T=8, n_points=256, release_lift_m=h), templates).eval()(
        b["xyz"], b["scale"], b["family"], b["contact"])["aligned"] for h in (0.0, 0.003))
    moved_m = (lifted - flat) * b["scale"][:, None, None]
    assert torch.allclose(moved_m, torch.tensor([0.0, 0.0, 0.003]).expand_as(moved_m), atol=1e-7)
    # ξ_0 of the template lies at the contact plus the lift, in metres
    xi0 = flat[:, 0] * b["scale"][:, None] + b["centroid"] - torch.as_tensor(
        np.stack([s.contact for s in sup]), dtype=torch.float32)
    assert torch.allclose(xi0, templates[b["family"], 0], atol=1e-6)
    with pytest.raises(ValueError, match="release_lift_m"):
        SctdnConfig(k=2, T=8, release_lift_m=0.03)
    saved = json.loads(SctdnConfig(k=2, T=8, release_lift_m=0.003).to_json())
    assert SctdnConfig.from_json(json.dumps(saved)).release_lift_m == 0.003
    del saved["release_lift_m"]  # a config saved before the lift: at the contact
    assert SctdnConfig.from_json(json.dumps(saved)).release_lift_m == 0.0

    train = [_lifted(s, [[0.0, 0.0, 0.002]]) for s in sup[:3]]
    val = [_lifted(sup[3], [[0.0, 0.0, 0.009]])]
    st = TrainSettings(epochs=1, views_per_epoch=1, batch_size=3, lr=1e-3, lr_final_ratio=0.1,
                       weight_decay=0.0, val_views=(0,), contact_weight=0.1, threads=1)
    model, _ = train_sctdn(SctdnConfig(k=2, T=8, n_points=256), np.zeros((2, 8, 3)), train, val, st, seed=0)
    assert model.cfg.release_lift_m == pytest.approx(0.002)  # the training supports', not val's


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


class _FixedNet(torch.nn.Module):
    """A fixed stand-in for Sctdn with outputs known in advance: family 2 (logits), the
    affordance peaks at the point nearest ``target`` (normalised frame), the deformed
    trajectory is the aligned one shifted by +0.1 (normalised units) in x."""

    def __init__(self, cfg, target):
        super().__init__()
        self.cfg, self.target = cfg, torch.as_tensor(target, dtype=torch.float32)
        # Sctdn's stored templates (metres from ξ_0), which the predictor reads when it loads
        line = torch.linspace(0, 1, cfg.T)[:, None] * torch.tensor([0.03, 0.0, 0.05])
        self.register_buffer("templates", line.expand(cfg.k, -1, -1).clone())

    def forward(self, xyz_n, scale):
        b = xyz_n.shape[0]
        aff = torch.exp(-((xyz_n - self.target) ** 2).sum(-1))
        contact = xyz_n[torch.arange(b), aff.argmax(-1)]
        aligned = contact[:, None] + torch.linspace(0, 1, self.cfg.T)[None, :, None] * \
            torch.tensor([0.3, 0.0, 0.5])
        return {"logits": torch.tensor([[0.1, -2.0, 3.0, 0.5]]).expand(b, -1), "affordance": aff,
                "aligned": aligned, "trajectory": aligned + torch.tensor([0.1, 0.0, 0.0])}


def test_predictor_inference_path_on_a_fixed_model():
    """argmax family, contact = the input point under the affordance argmax (in metres, in
    the support frame), positions de-normalised, frames by the SKT rule, deform switch."""
    cfg = SctdnConfig(k=4, T=6, n_points=200)
    rng = np.random.default_rng(4)
    pts = rng.normal(size=(200, 3)) * 0.04 + [0.1, 0.0, 0.2]
    c = pts.mean(0)
    s = np.linalg.norm(pts - c, axis=1).max()
    target = np.array([0.6, -0.3, 0.2])  # normalised frame
    k = int(np.argmin(np.linalg.norm((pts - c) / s - target, axis=1)))
    pred = SktPredictor(_FixedNet(cfg, target))
    skt = pred.predict(pts)
    assert skt.family == 2
    assert np.allclose(skt.contact, pts[k], atol=1e-12)  # a real input point, metres
    expected = pts[k] + np.outer(np.linspace(0, 1, 6), [0.3 * s, 0.0, 0.5 * s]) + [0.1 * s, 0, 0]
    assert np.allclose(skt.positions, expected, atol=1e-6)
    assert skt.affordance.shape == (200,) and int(skt.affordance.argmax()) == k
    assert np.allclose(skt.frames[:, :3, 3], skt.positions)
    aligned = pred.predict(pts, deform=False)
    assert np.allclose(aligned.positions, expected - [0.1 * s, 0, 0], atol=1e-6)
    # more points than the model takes: resampled by FPS, the contact is still an input point
    many = np.vstack([pts, rng.normal(size=(50, 3)) * 0.04 + [0.1, 0.0, 0.2]])
    skt2 = pred.predict(many)
    assert (np.linalg.norm(many - skt2.contact, axis=1) < 1e-12).any()


def test_predictor_matches_the_network_on_a_real_small_model():
    cfg = SctdnConfig(k=3, T=8, n_points=256)
    with torch.random.fork_rng():
        torch.manual_seed(7)
        model = Sctdn(cfg, torch.randn(3, 8, 3) * 0.02)
        with torch.no_grad():  # a non-zero deformation head, so trajectory ≠ aligned
            model.offset.weight.normal_(0, 0.1)
    pred = SktPredictor(model)
    pts = _supports()[1].points[0].astype(np.float64)
    skt = pred.predict(pts)
    xyz_n, c, s = normalise(pts)
    with torch.no_grad():
        out = model(torch.as_tensor(xyz_n[None], dtype=torch.float32),
                    torch.as_tensor([s], dtype=torch.float32))
    assert skt.family == int(out["logits"][0].argmax())
    assert np.array_equal(skt.contact, pts[int(out["affordance"][0].argmax())])
    assert np.allclose(skt.positions, out["trajectory"][0].double().numpy() * s + c)
    assert not np.allclose(skt.positions, pred.predict(pts, deform=False).positions)


def test_contact_target_is_the_views_contact_map_as_a_distribution():
    """make_batch turns the stored M_cp of each item's own view into a distribution over its
    points (the contact cross-entropy's target): view 1 of support 0 is not view 0."""
    sup = _supports()
    cp = np.random.default_rng(1).random((2, 256)).astype(np.float32)
    sup[0] = SupportData(**{**sup[0].__dict__, "contact_map": cp})
    b = make_batch([(sup[0], 1), (sup[1], 0)])
    t = b["contact_target"].double().numpy()
    assert t[0] == pytest.approx(cp[1] / cp[1].sum(), rel=1e-5)
    assert t[1] == pytest.approx(sup[1].contact_map[0] / sup[1].contact_map[0].sum(), rel=1e-5)


def test_contact_rate_counts_only_views_where_the_contact_is_seen():
    from skt_lib.learning.train import summarise

    per = {"traj_mm": np.ones(4), "template_mm": np.ones(4), "aff_mse": np.zeros(4),
           "cls_ok": np.ones(4), "contact_err_m": np.array([0.005, 0.02, 0.5, 0.01]),
           "contact_visible": np.array([True, True, False, True])}
    assert summarise(per)["val_contact_within_1cm_rate"] == pytest.approx(2 / 3)  # 1 cm counts
    per["contact_visible"][:] = False
    assert summarise(per)["val_contact_within_1cm_rate"] is None


def test_validation_intervals_wilson_for_rates_bootstrap_over_supports_for_errors():
    from skt_lib.learning.train import intervals
    from skt_lib.stats import wilson_interval

    per = {"traj_mm": np.array([1.0, 3.0, 10.0, 12.0]), "template_mm": np.full(4, 5.0),
           "aff_mse": np.zeros(4), "cls_ok": np.array([1.0, 0.0, 1.0, 1.0]),
           "contact_err_m": np.array([0.005, 0.02, 0.5, 0.01]),
           "contact_visible": np.array([True, True, False, True])}
    ci = intervals(per, ["a", "a", "b", "b"], np.random.default_rng(0))
    assert ci["val_cls_acc_ci95"] == pytest.approx(list(wilson_interval(3, 4)))
    assert ci["val_contact_within_1cm_rate_ci95"] == pytest.approx(list(wilson_interval(2, 3)))
    # two supports with means 2 and 11: resamples give 2, 6.5 or 11
    assert ci["val_traj_l2_mm_ci95"] == pytest.approx([2.0, 11.0])
    assert ci["val_template_only_l2_mm_ci95"] == pytest.approx([5.0, 5.0])
    per["contact_visible"][:] = False
    assert intervals(per, ["a", "a", "b", "b"], np.random.default_rng(0))[
        "val_contact_within_1cm_rate_ci95"] is None
