import numpy as np
import pytest
import torch

from skt_lib.learning.pointnet2 import (
    FeaturePropagation, SetAbstraction, _ball_query_kdtree, _ball_query_torch, _fps_torch,
    ball_query, ball_query_naive, fps, fps_naive, gather,
)

BALL_QUERIES = [ball_query, _ball_query_kdtree, _ball_query_torch]
from skt_lib.learning.sctdn import masked_max_pool, traj_distance


@pytest.mark.parametrize("n,npoint", [(64, 16), (500, 128)])
def test_fps_fast_and_torch_match_naive(n, npoint):
    xyz = torch.randn(2, n, 3, generator=torch.Generator().manual_seed(n))
    ref = fps_naive(xyz, npoint)
    assert torch.equal(fps(xyz, npoint), ref)
    assert torch.equal(_fps_torch(xyz, npoint), ref)


@pytest.mark.parametrize("bq", BALL_QUERIES)
def test_ball_query_matches_naive(bq):
    """Both implementations (CPU KD-tree, any-device dense) against the loops; groups both
    shorter and longer than nsample (then the nearest are kept), and nsample > N."""
    g = torch.Generator().manual_seed(0)
    xyz = torch.rand(2, 80, 3, generator=g)
    centres = xyz[:, :10]
    for r, k in ((0.3, 8), (0.15, 8), (0.5, 40), (0.9, 100)):
        assert torch.equal(bq(r, k, xyz, centres), ball_query_naive(r, k, xyz, centres))
    idx = bq(1e-6, 4, xyz, centres)  # only the centre itself
    assert torch.equal(idx, torch.arange(10).expand(2, 10)[..., None].expand(2, 10, 4))


def test_gather_shapes():
    pts = torch.arange(24.0).reshape(2, 4, 3)
    idx = torch.tensor([[[0, 3]], [[1, 1]]])
    out = gather(pts, idx)
    assert out.shape == (2, 1, 2, 3) and torch.equal(out[1, 0, 0], pts[1, 1])


# --- SetAbstraction, FeaturePropagation: each against a slow loop twin (eval mode) ---------


def _randomise(module: torch.nn.Module, seed: int) -> torch.nn.Module:
    """Random weights and BatchNorm statistics, eval mode: every layer does something."""
    g = torch.Generator().manual_seed(seed)
    with torch.no_grad():
        for m in module.modules():
            if isinstance(m, (torch.nn.BatchNorm1d, torch.nn.BatchNorm2d)):
                m.running_mean.copy_(torch.randn(m.num_features, generator=g) * 0.1)
                m.running_var.copy_(torch.rand(m.num_features, generator=g) + 0.5)
                m.weight.copy_(torch.rand(m.num_features, generator=g) + 0.5)
                m.bias.copy_(torch.randn(m.num_features, generator=g) * 0.1)
    return module.eval()


def _mlp_on_points(mlp, x):
    """The shared MLP on one set of points ``x (K, C)`` → ``(K, C')``: 1×1 convs are per point."""
    if isinstance(mlp[0], torch.nn.Conv2d):
        return mlp(x.T[None, :, :, None])[0, :, :, 0].T
    return mlp(x.T[None])[0].T


def set_abstraction_naive(sa: SetAbstraction, xyz, feats):
    """Reference: FPS centres, ball groups, relative coordinates then features, MLP per point,
    max over each group — loops over clouds and centres."""
    b, n, _ = xyz.shape
    if sa.npoint is None:
        new_xyz = torch.zeros(b, 1, 3)
        groups = [[list(range(n))] for _ in range(b)]
    else:
        centres = fps_naive(xyz, sa.npoint)
        new_xyz = torch.stack([xyz[i, centres[i]] for i in range(b)])
        groups = ball_query_naive(sa.radius, sa.nsample, xyz, new_xyz).tolist()
    out = []
    for i in range(b):
        cols = []
        for s, members in enumerate(groups[i]):
            rows = []
            for j in members:
                rel = xyz[i, j] - new_xyz[i, s]
                rows.append(rel if feats is None else torch.cat([rel, feats[i, :, j]]))
            cols.append(_mlp_on_points(sa.mlp, torch.stack(rows)).max(0).values)
        out.append(torch.stack(cols, 1))
    return new_xyz, torch.stack(out)


def feature_propagation_naive(fp: FeaturePropagation, xyz_fine, xyz_coarse, feats_fine,
                              feats_coarse):
    """Reference: for each fine point, the (up to) 3 nearest coarse points, weights 1/d
    normalised, interpolated coarse features, then the skip features, then the MLP."""
    b, n, _ = xyz_fine.shape
    out = []
    for i in range(b):
        cols = []
        for p in range(n):
            d = [float(torch.linalg.norm(xyz_fine[i, p] - q)) for q in xyz_coarse[i]]
            near = sorted(range(len(d)), key=d.__getitem__)[:3]
            w = [1.0 / (d[j] + 1e-8) for j in near]
            f = sum(wj / sum(w) * feats_coarse[i, :, j] for wj, j in zip(w, near))
            cols.append(f if feats_fine is None else torch.cat([f, feats_fine[i, :, p]]))
        x = torch.stack(cols)  # (N, C)
        out.append(_mlp_on_points(fp.mlp, x).T)
    return torch.stack(out)


@pytest.mark.parametrize("npoint,with_feats", [(12, True), (12, False), (None, True),
                                               (None, False)])
def test_set_abstraction_matches_naive(npoint, with_feats):
    g = torch.Generator().manual_seed(3)
    xyz = torch.rand(2, 60, 3, generator=g) - 0.5
    feats = torch.randn(2, 4, 60, generator=g) if with_feats else None
    c_in = 3 + (4 if with_feats else 0)
    with torch.random.fork_rng():
        torch.manual_seed(0)
        sa = _randomise(SetAbstraction(npoint, 0.3, 8, [c_in, 16, 24]), 1)
    with torch.no_grad():
        new_xyz, out = sa(xyz, feats)
        ref_xyz, ref = set_abstraction_naive(sa, xyz, feats)
    assert out.shape == (2, 24, npoint or 1)
    assert torch.equal(new_xyz, ref_xyz)
    assert torch.allclose(out, ref, atol=1e-5)
    assert out.std() > 0.01  # not a degenerate all-zero output


@pytest.mark.parametrize("n_coarse,with_skip", [(10, True), (10, False), (2, True)])
def test_feature_propagation_matches_naive(n_coarse, with_skip):
    g = torch.Generator().manual_seed(n_coarse)
    xyz_f, xyz_c = torch.rand(2, 25, 3, generator=g), torch.rand(2, n_coarse, 3, generator=g)
    f_c = torch.randn(2, 6, n_coarse, generator=g)
    f_f = torch.randn(2, 5, 25, generator=g) if with_skip else None
    with torch.random.fork_rng():
        torch.manual_seed(0)
        fp = _randomise(FeaturePropagation([6 + (5 if with_skip else 0), 16, 8]), 2)
    with torch.no_grad():
        out = fp(xyz_f, xyz_c, f_f, f_c)
        ref = feature_propagation_naive(fp, xyz_f, xyz_c, f_f, f_c)
    assert out.shape == (2, 8, 25) and torch.allclose(out, ref, atol=1e-5)
    assert out.std() > 0.01


def test_feature_propagation_reproduces_features_at_the_coarse_points():
    """A fine point on a coarse point takes (almost) exactly that point's features."""
    g = torch.Generator().manual_seed(5)
    xyz_c = torch.rand(1, 7, 3, generator=g)
    f_c = torch.randn(1, 4, 7, generator=g)
    fp = FeaturePropagation([4, 4]).eval()
    with torch.no_grad():
        fp.mlp[0].weight.copy_(torch.eye(4)[:, :, None])
        fp.mlp[0].bias.zero_()
        out = fp(xyz_c, xyz_c, None, f_c)
    assert torch.allclose(out, torch.relu(f_c), atol=1e-5)


# --- the masked max-pool and the padded trajectory distance (skt_lib/learning/sctdn.py) ------


def masked_max_pool_naive(feats, aff, threshold):
    out = torch.empty(feats.shape[:2])
    for b in range(feats.shape[0]):
        keep = [j for j in range(feats.shape[2]) if float(aff[b, j]) > threshold]
        keep = keep or list(range(feats.shape[2]))
        for c in range(feats.shape[1]):
            out[b, c] = max(float(feats[b, c, j]) for j in keep)
    return out


def test_masked_max_pool_matches_naive():
    g = torch.Generator().manual_seed(0)
    feats = torch.rand(4, 6, 50, generator=g) * 3
    aff = torch.rand(4, 50, generator=g) * 0.3
    aff[1] = 0.05  # nothing above the threshold: pool over every point
    aff[2, :10] = 0.25  # exactly at the threshold: not above it
    aff[2, 10:] = 0.0
    aff[2, 3] = 0.5  # one point: its features
    feats[:, :, 0] = 10.0  # the largest features, on a point masked out in clouds 0, 2, 3
    aff[0, 0] = aff[2, 0] = aff[3, 0] = 0.0
    out = masked_max_pool(feats, aff, 0.25)
    assert torch.allclose(out, masked_max_pool_naive(feats, aff, 0.25))
    assert torch.equal(out[2], feats[2, :, 3]) and torch.equal(out[1], feats[1].max(-1).values)
    assert (out[[0, 2, 3]] < 10.0).all() and (out[1] == 10.0).all()


def traj_distance_naive(pred, gt, valid):
    out = []
    for b in range(pred.shape[0]):
        ds = [float(torch.linalg.norm(pred[b] - gt[b, k], dim=-1).mean())
              for k in range(gt.shape[1]) if bool(valid[b, k])]
        out.append(min(ds))
    return torch.tensor(out)


def test_traj_distance_ignores_padding_and_matches_naive():
    """Supports with 1, 3 and 2 ground-truth SKTs: make_batch pads to 3 with zeros; a padded
    slot must never be the nearest, even where the prediction sits on it."""
    from skt_lib.learning.data import SupportData
    from skt_lib.learning.train import make_batch

    rng = np.random.default_rng(0)
    sup = []
    for i, n_skts in enumerate((1, 3, 2)):
        pts = rng.normal(size=(1, 64, 3)).astype(np.float32) * 0.05
        skts = rng.normal(size=(n_skts, 6, 3)) * 0.05 + 0.2
        sup.append(SupportData(f"s{i}", "train", 0, pts, np.zeros((1, 64), np.float32), skts,
                               np.zeros(3), np.ones((1, 64), np.float32), np.ones(1, bool)))
    b = make_batch([(s, 0) for s in sup])
    assert b["gt"].shape == (3, 3, 6, 3)
    assert b["valid"].tolist() == [[True, False, False], [True, True, True], [True, True, False]]
    pred = torch.zeros(3, 6, 3)  # exactly on the zero padding
    pred[1] = b["gt"][1, 2] + 0.01  # near the third SKT of support 1
    d = traj_distance(pred, b["gt"], b["valid"])
    assert torch.allclose(d, traj_distance_naive(pred, b["gt"], b["valid"]))
    assert d[1] == pytest.approx(0.01 * np.sqrt(3), rel=1e-4)
    assert (d[[0, 2]] > 0.5).all()  # the padding (at the prediction) is never chosen
    assert torch.isinf(traj_distance(pred, b["gt"], torch.zeros(3, 3, dtype=torch.bool))).all()


def test_shared_mlps_are_conv_batchnorm_relu_per_layer():
    sa, fp = SetAbstraction(8, 0.2, 4, [7, 16, 32]), FeaturePropagation([5, 12, 6])
    for seq, conv, bn, widths in ((sa.mlp, torch.nn.Conv2d, torch.nn.BatchNorm2d, [7, 16, 32]),
                                  (fp.mlp, torch.nn.Conv1d, torch.nn.BatchNorm1d, [5, 12, 6])):
        assert [type(m) for m in seq] == [conv, bn, torch.nn.ReLU] * 2
        assert [(m.in_channels, m.out_channels) for m in seq[::3]] == list(zip(widths, widths[1:]))
        assert all(m.kernel_size in ((1, 1), (1,)) for m in seq[::3])
        assert [m.num_features for m in seq[1::3]] == widths[1:]
    assert (sa.npoint, sa.radius, sa.nsample) == (8, 0.2, 4)


@pytest.mark.parametrize("ball_query", BALL_QUERIES)
def test_ball_query_boundary_far_from_origin_and_empty_groups(ball_query):
    # a point exactly at the radius is inside (d² = r² exactly, in float32 too)
    xyz = torch.tensor([[[0.0, 0, 0], [0.5, 0, 0], [1.0, 0, 0], [0.25, 0, 0]]])
    expected = torch.tensor([[[0, 3, 1, 0]]])  # nearest first, padded with the nearest
    assert torch.equal(ball_query(0.5, 4, xyz, xyz[:, :1]), expected)
    assert torch.equal(ball_query_naive(0.5, 4, xyz, xyz[:, :1]), expected)
    # 1 km from the origin the matrix-product distance form loses the centimetres: exact
    # differences must still agree with the naive loops
    g = torch.Generator().manual_seed(2)
    far = torch.rand(1, 60, 3, generator=g) * 0.05 + 1000.0
    assert torch.equal(ball_query(0.02, 6, far, far[:, :12]),
                       ball_query_naive(0.02, 6, far, far[:, :12]))
    # a centre with no point within the radius: the group is its nearest point, repeated
    centres = torch.tensor([[[0.1, 0.0, 0.0], [0.8, 0.01, 0.0]]])
    assert torch.equal(ball_query(0.01, 3, xyz, centres), torch.tensor([[[0] * 3, [2] * 3]]))


def test_ops_keep_the_input_device():
    """On PyTorch's data-free ``meta`` device (a stand-in for CUDA): every tensor an op
    creates lives on the input's device; a buffer created on the CPU fails here."""
    x = torch.rand(2, 30, 3, device="meta")
    idx = fps(x, 5)
    assert idx.device.type == "meta" and idx.dtype == torch.int64 and idx.shape == (2, 5)
    q = ball_query(0.3, 4, x, x[:, :5])
    assert q.device.type == "meta" and q.dtype == torch.int64 and q.shape == (2, 5, 4)
    sa = SetAbstraction(None, 0.0, 0, [3, 8]).to("meta").eval()
    new_xyz, f = sa(x, None)
    assert new_xyz.device.type == "meta" and new_xyz.shape == (2, 1, 3) and f.shape == (2, 8, 1)


def test_fps_routes_cpu_to_open3d_and_other_devices_to_torch(monkeypatch):
    from skt_lib.learning import pointnet2

    calls, real = [], pointnet2._fps_torch
    monkeypatch.setattr(pointnet2, "_fps_torch",
                        lambda xyz, n: calls.append((xyz.device.type, n)) or real(xyz, n))
    x = torch.rand(2, 40, 3, generator=torch.Generator().manual_seed(1))
    assert fps(x, 6).dtype == torch.int64 and calls == []
    assert fps(x.to("meta"), 6).shape == (2, 6) and calls == [("meta", 6)]
    assert _fps_torch(x, 6).dtype == torch.int64


@pytest.mark.parametrize("make", [lambda: SetAbstraction(8, 0.2, 4, [7, 16, 32]).mlp,
                                  lambda: FeaturePropagation([5, 12, 6]).mlp])
def test_fused_mlp_is_the_eval_mode_modules(make):
    """The fused inference path (BatchNorm folded into each 1×1 conv) computes exactly what
    the conv/BatchNorm/ReLU modules compute in eval mode — with running variances small
    enough that dropping BatchNorm's eps, or a layer's bias, would show."""
    from skt_lib.learning.pointnet2 import fused_mlp

    with torch.random.fork_rng():
        torch.manual_seed(0)
        seq = make()
    g = torch.Generator().manual_seed(4)
    with torch.no_grad():
        for m in seq:
            if isinstance(m, (torch.nn.BatchNorm1d, torch.nn.BatchNorm2d)):
                m.running_mean.copy_(torch.randn(m.num_features, generator=g) * 0.1)
                m.running_var.copy_(torch.rand(m.num_features, generator=g) * 1e-4 + 1e-5)
                m.weight.copy_(torch.rand(m.num_features, generator=g) + 0.5)
                m.bias.copy_(torch.randn(m.num_features, generator=g) * 0.1)
    seq.eval()
    c_in = seq[0].in_channels
    x = torch.randn(3, 5, c_in, generator=g) * 0.01
    with torch.no_grad():
        fused = fused_mlp(seq, x)
        if isinstance(seq[0], torch.nn.Conv2d):
            ref = seq(x.permute(2, 0, 1)[None, :, :, :]).permute(0, 2, 3, 1)[0]
        else:
            ref = seq(x.reshape(-1, c_in).T[None])[0].T.reshape(3, 5, -1)
    assert fused.shape == ref.shape and (ref > 0).any()
    assert torch.allclose(fused, ref, rtol=1e-4, atol=1e-5)


@pytest.mark.parametrize("n_coarse", [1, 2, 40])
def test_three_nn_kdtree_and_dense_match_the_loops(n_coarse):
    from skt_lib.learning.pointnet2 import three_nn

    g = torch.Generator().manual_seed(n_coarse)
    fine, coarse = torch.rand(2, 30, 3, generator=g), torch.rand(2, n_coarse, 3, generator=g)
    k = min(3, n_coarse)
    ref_d = torch.empty(2, 30, k)
    ref_i = torch.empty(2, 30, k, dtype=torch.long)
    for b in range(2):
        for p in range(30):
            d = [float(torch.linalg.norm(fine[b, p] - q)) for q in coarse[b]]
            order = sorted(range(n_coarse), key=d.__getitem__)[:k]
            ref_i[b, p] = torch.tensor(order)
            ref_d[b, p] = torch.tensor([d[j] for j in order])
    for d, i in (three_nn(fine, coarse), three_nn(fine.to("meta"), coarse.to("meta"))):
        assert d.shape == (2, 30, k) and i.shape == (2, 30, k)
    d, i = three_nn(fine, coarse)  # CPU: KD-tree
    assert torch.equal(i, ref_i) and torch.allclose(d, ref_d, atol=1e-6) and d.dtype == torch.float32
    d2, i2 = torch.cdist(fine, coarse).topk(k, dim=-1, largest=False)  # the dense path's op
    assert torch.equal(i2, ref_i) and torch.allclose(d2, ref_d, atol=1e-6)


def test_training_path_equals_the_fused_inference_path():
    """SetAbstraction/FeaturePropagation in training mode run the conv modules; in eval mode
    the fused matmuls. With BatchNorm held on its running statistics (the only thing that
    differs by design) both paths compute the same function, each layer included."""
    g = torch.Generator().manual_seed(7)
    xyz = torch.rand(2, 60, 3, generator=g) - 0.5
    feats = torch.randn(2, 4, 60, generator=g)
    with torch.random.fork_rng():
        torch.manual_seed(0)
        sa = _randomise(SetAbstraction(12, 0.3, 8, [7, 16, 24]), 1)
        sa_g = _randomise(SetAbstraction(None, 0.0, 0, [7, 16]), 3)
        fp = _randomise(FeaturePropagation([24 + 4, 16, 8]), 2)
    with torch.no_grad():
        ref_xyz, ref = sa(xyz, feats)
        ref_g = sa_g(xyz, feats)[1]
        ref_fp = fp(xyz, ref_xyz, feats, ref)
        for m in (sa, sa_g, fp):
            m.train()
            for bn in m.modules():
                if isinstance(bn, (torch.nn.BatchNorm1d, torch.nn.BatchNorm2d)):
                    bn.eval()
        new_xyz, out = sa(xyz, feats)
        assert torch.equal(new_xyz, ref_xyz) and torch.allclose(out, ref, atol=1e-5)
        assert torch.allclose(sa_g(xyz, feats)[1], ref_g, atol=1e-5)
        assert torch.allclose(fp(xyz, ref_xyz, feats, ref), ref_fp, atol=1e-5)


@pytest.mark.parametrize("pairs", [0, 10**9])
def test_kdtree_and_dense_routes_agree_inside_the_network(monkeypatch, pairs):
    """The same SA/FP outputs whichever route (KD-tree or dense) the size threshold picks."""
    from skt_lib.learning import pointnet2

    g = torch.Generator().manual_seed(9)
    xyz = torch.rand(1, 200, 3, generator=g) - 0.5
    with torch.random.fork_rng():
        torch.manual_seed(0)
        sa = _randomise(SetAbstraction(40, 0.25, 8, [3, 16]), 1)
        fp = _randomise(FeaturePropagation([16, 8]), 2)
    with torch.no_grad():
        ref_xyz, ref = sa(xyz, None)
        ref_fp = fp(xyz, ref_xyz, None, ref)
        monkeypatch.setattr(pointnet2, "KDTREE_MIN_PAIRS", pairs)
        new_xyz, out = sa(xyz, None)
        assert torch.allclose(out, ref, atol=1e-6)
        # the dense 3-NN uses cdist's matrix-product form: a fine point on a coarse point gets
        # a distance of ~1e-4 there, 0 on the KD-tree — the interpolation differs by that much
        assert torch.allclose(fp(xyz, new_xyz, None, out), ref_fp, atol=1e-3)


def test_the_size_threshold_routes_large_cpu_inputs_to_the_kdtree(monkeypatch):
    from skt_lib.learning import pointnet2

    calls = []
    real_bq, real_nn = pointnet2._ball_query_kdtree, pointnet2.cKDTree
    monkeypatch.setattr(pointnet2, "_ball_query_kdtree",
                        lambda *a: calls.append("bq") or real_bq(*a))
    monkeypatch.setattr(pointnet2, "cKDTree", lambda *a, **k: calls.append("tree") or real_nn(*a, **k))
    xyz = torch.rand(1, 1000, 3, generator=torch.Generator().manual_seed(1))
    pointnet2.ball_query(0.1, 8, xyz, xyz[:, :19])  # 19 000 pairs: dense
    pointnet2.three_nn(xyz[:, :100], xyz[:, :199])  # 19 900 pairs: dense
    assert calls == []
    pointnet2.ball_query(0.1, 8, xyz, xyz[:, :20])  # 20 000 pairs: KD-tree
    pointnet2.three_nn(xyz[:, :100], xyz[:, :200])
    assert calls.count("bq") == 1 and calls.count("tree") >= 2
    calls.clear()
    pointnet2.ball_query(0.1, 8, xyz.requires_grad_(), xyz[:, :20].detach())  # gradients: dense
    assert calls == []


def _memo_supports(n=4, views=3, T=8, n_points=512):
    from skt_lib.learning.data import SupportData

    rng = np.random.default_rng(0)
    out = []
    for i in range(n):
        pts = rng.normal(size=(views, n_points, 3)).astype(np.float32) * 0.05
        contact = pts[0, 0].astype(np.float64)
        skt = contact + np.outer(np.linspace(0, 1, T), [0.1, 0.02 * i, 0.05])
        aff = np.exp(-np.linalg.norm(pts - contact, axis=-1) ** 2 / 2e-4).astype(np.float32)
        out.append(SupportData(f"s{i}", "train", i % 2, pts, aff, skt[None], contact, aff,
                               np.ones(views, bool)))
    return out


def test_geometry_memo_gives_the_same_weights_and_skips_repeated_searches(monkeypatch):
    """Training with the per-cloud memo is training without it, bit for bit (every weight
    and every validation figure), and a cloud seen before is not searched again."""
    from dataclasses import replace

    from skt_lib.learning import pointnet2
    from skt_lib.learning.sctdn import SctdnConfig
    from skt_lib.learning.train import TrainSettings, make_batch, train_sctdn

    sup = _memo_supports()
    cfg = SctdnConfig(k=2, T=8, n_points=512)
    st = TrainSettings(epochs=3, views_per_epoch=2, batch_size=3, lr=1e-3, lr_final_ratio=0.1,
                       weight_decay=0.0, val_views=(0, 2), contact_weight=0.1, threads=1)
    templates = np.zeros((2, 8, 3))

    def train():
        model, best = train_sctdn(cfg, templates, sup[:3], sup[3:], st, seed=5)
        return model.state_dict(), best

    real = pointnet2._per_cloud
    computed = []
    with monkeypatch.context() as m:  # fit keeps its own memo: bypass it for the plain run
        m.setattr(pointnet2, "_per_cloud", lambda op, args, arrays, compute: compute())
        plain_w, plain_best = train()
    monkeypatch.setattr(pointnet2, "_per_cloud", lambda op, args, arrays, compute: real(
        op, args, arrays, lambda: computed.append(op) or compute()))
    with pointnet2.geometry_memo():
        memo_w, memo_best = train()  # fit's memo is this outer one: shared, kept after it
        kept = len(pointnet2._memo)
    monkeypatch.setattr(pointnet2, "_per_cloud", real)
    assert pointnet2._memo is None and 0 < kept == len(computed)
    # at these sizes the first level's ball query and the finest 3-NN take the KD-tree
    assert {"fps", "ball_query", "three_nn"} <= set(computed)
    assert {"fps", "ball_query", "three_nn"} <= _ops_seen(monkeypatch, sup)
    assert plain_best == memo_best
    assert plain_w.keys() == memo_w.keys()
    for k in plain_w:
        assert torch.equal(plain_w[k], memo_w[k]), k

    # inside the memo: the second pass over the same clouds runs no search at all
    calls = []
    real_tree, real_fps = pointnet2.cKDTree, pointnet2._fps_cloud
    monkeypatch.setattr(pointnet2, "cKDTree",
                        lambda *a, **k: calls.append("tree") or real_tree(*a, **k))
    monkeypatch.setattr(pointnet2, "_fps_cloud", lambda *a: calls.append("fps") or real_fps(*a))
    model, _ = train_sctdn(cfg, templates, sup[:3], sup[3:], replace(st, epochs=1), seed=5)
    model.eval()
    b = make_batch([(s, v) for s in sup for v in range(3)])
    with pointnet2.geometry_memo(), torch.no_grad():
        first = model(b["xyz"], b["scale"], b["family"], b["contact"])
        n_first = len(calls)
        again = model(b["xyz"], b["scale"], b["family"], b["contact"])
    assert n_first > 0 and len(calls) == n_first
    for k in first:
        assert torch.equal(first[k], again[k]), k


def _ops_seen(monkeypatch, sup):
    """The ops that stored something in the memo on one batch of ``sup``."""
    from skt_lib.learning import pointnet2

    seen = []
    real = pointnet2._per_cloud
    monkeypatch.setattr(pointnet2, "_per_cloud",
                        lambda op, *a: seen.append(op) or real(op, *a))
    from skt_lib.learning.sctdn import Sctdn, SctdnConfig
    from skt_lib.learning.train import make_batch

    b = make_batch([(s, 0) for s in sup])
    with torch.no_grad():
        Sctdn(SctdnConfig(k=2, T=8, n_points=512), torch.zeros(2, 8, 3)).eval()(
            b["xyz"], b["scale"], b["family"], b["contact"])
    monkeypatch.setattr(pointnet2, "_per_cloud", real)
    return set(seen)
