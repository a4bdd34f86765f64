import numpy as np
import pytest

from skt_lib.labels.affordance import (
    affordance, contact_map, hanging_part, segmentation_map, segmentation_map_naive,
)
from skt_lib.labels.families import fit_families
from skt_lib.labels.templates import fit_pca, kmeans, silhouette


def test_affordance_on_a_hand_computed_case():
    pts = np.array([[0.0, 0, 0], [0.01, 0, 0], [0.02, 0, 0], [0.0, 0.005, 0]])
    sigma = 0.005
    m_cp, k = contact_map(pts, np.array([0.009, 0.001, 0]), sigma)
    assert k == 1
    assert m_cp == pytest.approx(np.exp(-0.5 * np.array([4, 0, 4, 5]))) # d²/σ² = 4, 0, 4, 5
    m_seg = segmentation_map(pts, np.array([[0.021, 0, 0], [0.0, 0.006, 0]]), sigma)
    # anchors: points 2 and 3; point 0 is 5 mm from point 3, point 1 is 10 mm from point 2
    assert m_seg == pytest.approx([np.exp(-0.5), np.exp(-2.0), 1.0, 1.0])
    a, _, _, _ = affordance(pts, np.array([0.009, 0.001, 0]), np.array([[0.021, 0, 0]]), sigma, 0.5, 0.5)
    assert a.dtype == np.float32 and a[1] == pytest.approx(0.5 + 0.5 * np.exp(-2.0), rel=1e-6)


def test_segmentation_map_matches_naive():
    rng = np.random.default_rng(3)
    pts, wps = rng.normal(size=(60, 3)) * 0.02, rng.normal(size=(7, 3)) * 0.02
    assert segmentation_map(pts, wps, 0.006) == pytest.approx(segmentation_map_naive(pts, wps, 0.006))


def test_maps_do_not_depend_on_point_order():
    rng = np.random.default_rng(4)
    pts = rng.normal(size=(200, 3)) * 0.03
    contact, wps = np.array([0.01, 0, 0]), rng.normal(size=(5, 3)) * 0.01
    perm = rng.permutation(200)
    a, *_ = affordance(pts, contact, wps, 0.005, 0.5, 0.5)
    b, *_ = affordance(pts[perm], contact, wps, 0.005, 0.5, 0.5)
    assert b == pytest.approx(a[perm])


def test_hanging_part_is_the_first_stretch_of_arc():
    path = np.stack([np.linspace(0, 0.1, 101), np.zeros(101), np.zeros(101)], 1)
    assert len(hanging_part(path, 0.03)) == 31


def _family(kind, rng):
    s = np.linspace(0, 1, 60)
    base = {"straight": np.stack([0.15 * s, 0 * s, 0.05 * s], 1),
            "up": np.stack([0.15 * s, 0 * s, 0.12 * s**2], 1),
            "side": np.stack([0.10 * s, 0.08 * s, 0.02 * s], 1)}[kind]
    return base + rng.normal(scale=0.002, size=base.shape)


def test_families_recover_planted_clusters_deterministically():
    rng = np.random.default_rng(0)
    kinds = ["straight", "up", "side"]
    skts = {f"s{i:02d}": [_family(kinds[i % 3], rng) for _ in range(4)] for i in range(24)}
    train = {sid for i, sid in enumerate(sorted(skts)) if i < 18}
    a = fit_families(skts, train, 20, 3, np.random.default_rng(1), 5, 100)
    b = fit_families(skts, train, 20, 3, np.random.default_rng(1), 5, 100)
    assert a.labels == b.labels
    for kind in kinds:  # each planted family maps to exactly one cluster, val/test included
        got = {a.labels[f"s{i:02d}"] for i in range(24) if kinds[i % 3] == kind}
        assert len(got) == 1
    assert len(set(a.labels.values())) == 3
    assert a.silhouette > 0.7
    assert a.templates.shape == (3, 20, 3) and np.allclose(a.templates[:, 0], 0)
    assert all(sid in train for sid in a.template_support_ids)


def test_kmeans_and_pca_basics():
    rng = np.random.default_rng(2)
    x = np.vstack([rng.normal(size=(30, 2)) * 0.1 + c for c in ([0, 0], [5, 0], [0, 5])])
    centres, labels = kmeans(x, 3, rng)
    assert sorted(np.bincount(labels)) == [30, 30, 30]
    assert silhouette(x, labels) > 0.9
    with pytest.raises(ValueError, match="k: need"):
        kmeans(x[:2], 3, rng)
    pca = fit_pca(np.column_stack([np.arange(10.0), 2 * np.arange(10.0), np.zeros(10)]))
    assert np.abs(pca.components[0]) == pytest.approx(np.array([1, 2, 0]) / np.sqrt(5))


def test_agreement_is_the_share_of_a_supports_skts_in_its_family():
    """Planted families; support s00 gets one SKT of another family (agreement 3/4), s01 two
    of four (a tie: the lower family wins, agreement 1/2); every other support agrees fully."""
    rng = np.random.default_rng(0)
    kinds = ["straight", "up", "side"]
    skts = {f"s{i:02d}": [_family(kinds[i % 3], rng) for _ in range(4)] for i in range(24)}
    skts["s00"][3] = _family("up", rng)  # s00 is "straight"
    skts["s01"][2:] = [_family("side", rng), _family("side", rng)]  # s01 is "up"
    train = {sid for i, sid in enumerate(sorted(skts)) if i < 18}
    fam = fit_families(skts, train, 20, 3, np.random.default_rng(1), 5, 100)
    assert fam.agreement["s00"] == pytest.approx(0.75) and fam.agreement["s01"] == pytest.approx(0.5)
    assert all(fam.agreement[s] == 1.0 for s in skts if s not in ("s00", "s01"))
    assert fam.labels["s00"] == fam.labels["s03"]  # majority: its own family
    up, side = fam.labels["s04"], fam.labels["s05"]
    assert fam.labels["s01"] == min(up, side)
    assert {k: v.shape for k, v in fam.skt_embeddings.items()} == {s: (4, 2) for s in skts}


def test_families_cluster_supports_not_skts():
    """The centres are k-means of the training *supports* (each the mean PCA embedding of its
    SKTs), with the same generator — not of the individual SKTs, whose random spread let one
    support's SKTs straddle a boundary. Val/test supports never move the centres."""
    from skt_lib.labels.families import skt_features

    rng = np.random.default_rng(0)
    kinds = ["straight", "up", "side"]
    skts = {f"s{i:02d}": [_family(kinds[i % 3], rng) for _ in range(2 + (i // 3) % 3)]
            for i in range(24)}
    train = {sid for i, sid in enumerate(sorted(skts)) if i < 18}
    fam = fit_families(skts, train, 20, 3, np.random.default_rng(1), 5, 100)
    ids = sorted(train)
    feats = {sid: np.stack([skt_features(x, 20) for x in skts[sid]]) for sid in ids}
    pca = fit_pca(np.vstack([feats[sid] for sid in ids]))
    means = np.stack([pca.transform(feats[sid]).mean(0) for sid in ids])
    centres, _ = kmeans(means, 3, np.random.default_rng(1), 5, 100)
    assert fam.centres == pytest.approx(centres)
    skts["s23"] = [_family("up", rng) + 0.05 for _ in range(3)]  # a test support far off
    assert fit_families(skts, train, 20, 3, np.random.default_rng(1), 5, 100).centres == pytest.approx(centres)
