"""skt_flow's contact hypotheses: which points are picked, that each sample is the flow's from
its own hypothesis, that one hypothesis is the model's own ``propose``, and the order that
trusts the argmax."""

import numpy as np
import pytest
import torch

from skt_lib.eval.contact_hypotheses import ContactHypotheses, _tiers, contact_candidates, propose
from skt_lib.eval.methods import make_method
from skt_lib.learning.cloud_check import ring_penetrations
from skt_lib.learning.data import normalise
from skt_lib.learning.flow import FlowPredictor
from tests.learning.test_flow import T, _model
from tests.learning.test_sctdn import _supports


def _line():
    """26 points 2 mm apart along x, and an affordance with its peak at point 10."""
    pts = np.zeros((26, 3))
    pts[:, 0] = np.arange(26) * 0.002
    aff = np.full(26, 0.1)
    aff[[10, 11, 20, 0, 25]] = [1.0, 0.95, 0.8, 0.6, 0.45]
    return pts, aff


def test_candidates_are_the_argmax_then_the_most_afforded_points_far_enough_apart():
    pts, aff = _line()
    # 11 is 2 mm from the argmax (< 1 cm), 25 holds less than half the argmax's affordance
    assert contact_candidates(pts, aff, ContactHypotheses(3)).tolist() == [10, 20, 0]
    assert contact_candidates(pts, aff, ContactHypotheses(5)).tolist() == [10, 20, 0]
    assert contact_candidates(pts, aff, ContactHypotheses(2)).tolist() == [10, 20]
    assert contact_candidates(pts, aff, ContactHypotheses(1)).tolist() == [10]
    assert contact_candidates(pts, aff, ContactHypotheses(5, min_share=0.7)).tolist() == [10, 20]
    assert contact_candidates(pts, aff, ContactHypotheses(5, min_share=0.4)).tolist() == \
        [10, 20, 0, 25]
    assert contact_candidates(pts, aff, ContactHypotheses(5, spacing_m=0.03)).tolist() == [10]
    with pytest.raises(ValueError, match="n_contacts: need at least one"):
        contact_candidates(pts, aff, ContactHypotheses(0))


def test_one_hypothesis_is_the_models_own_propose_exactly():
    pred = FlowPredictor(_model())
    pts = _supports()[0].points[0].astype(np.float64)
    for seed in (0, 3):
        own = pred.propose(pts, np.random.default_rng(seed), n=7)
        one = propose(pred, pts, np.random.default_rng(seed), 7, ContactHypotheses(1))
        assert all(np.array_equal(a.positions, b.positions) and np.array_equal(a.contact, b.contact)
                   for a, b in zip(own, one))
    # make_method's default (flow_contacts = 1) runs it that way too
    method = make_method("skt_flow", pred, np.zeros((T, 3)), np.array([0.1, 0, 0]),
                         rng=np.random.default_rng(3), n_proposals=5)
    assert method.contacts == ContactHypotheses(1)


def test_each_sample_is_the_flow_from_its_own_hypothesis_drawn_in_turn():
    pred = FlowPredictor(_model())
    with torch.no_grad():  # an untrained backbone's points differ by 1e-4: make them count
        f, dim = pred.cfg.feat_dim, pred.cfg.dim
        pred.model.net[0].weight[:, dim + f:dim + 2 * f] *= 1000.0  # the contact's feature
    pts = _supports()[0].points[0].astype(np.float64)
    h = ContactHypotheses(3, min_share=0.0)
    skts = propose(pred, pts, np.random.default_rng(5), 10, h)
    xyz_n, c, s = normalise(pts)
    x = torch.as_tensor(xyz_n[None], dtype=torch.float32)
    with torch.inference_mode():
        enc = pred.model.encode_cloud(x)
        idx = contact_candidates(pts, enc["affordance"][0].numpy(), h)
        assert len(idx) == 3 and idx[0] == int(enc["affordance"][0].argmax())
        noise = torch.as_tensor(np.random.default_rng(5).standard_normal((10, pred.cfg.dim)),
                                dtype=torch.float32)
        expected = []
        for i in range(10):  # draw i from hypothesis i mod 3, its condition as encode_cloud's
            cp = x[0, int(idx[i % 3])][None]
            cond = pred.model.encode_cloud(x, cp)["cond"]
            expected.append(pred.model.sample(noise[i:i + 1], cond, cp)[0].double().numpy() * s + c)
    got = np.stack([k.positions for k in skts])
    match = [int(np.argmin(np.abs(got - e).max(axis=(1, 2)))) for e in expected]
    assert sorted(match) == list(range(10))  # every draw is there once
    assert all(np.allclose(got[m], e, atol=1e-6) for m, e in zip(match, expected))
    for i, m in enumerate(match):
        assert np.array_equal(skts[m].contact, pts[idx[i % 3]])


def test_the_argmax_yields_only_to_a_clear_sample_when_its_own_cut_deep():
    h = ContactHypotheses(3, deep_m2=100e-6, clear_m2=1e-6)
    scores = np.array([500e-6, 0.0, 50e-6, 2000e-6, 0.5e-6, 150e-6])
    other = np.array([False, True, False, True, True, False])
    assert _tiers(scores, other, h).tolist() == [2, 1, 0, 3, 1, 2]
    order = np.lexsort((scores, _tiers(scores, other, h)))
    # a shallow argmax sample first; then the others' clear ones; then the argmax's deep ones
    assert order.tolist() == [2, 1, 4, 5, 0, 3]


def test_propose_orders_by_tier_then_by_the_cloud_check():
    pred = FlowPredictor(_model())
    pts = _supports()[1].points[0].astype(np.float64)
    h = ContactHypotheses(3, min_share=0.0)
    skts = propose(pred, pts, np.random.default_rng(2), 9, h)
    scores = ring_penetrations([k.positions for k in skts], pts,
                               rotations=[k.frames[:, :3, :3] for k in skts])
    argmax = skts[0].affordance.argmax()
    other = np.array([not np.array_equal(k.contact, pts[argmax]) for k in skts])
    assert other.sum() == 6  # 9 draws over 3 hypotheses
    key = list(zip(_tiers(scores, other, h), scores))
    assert key == sorted(key)
