"""The cloud check (skt_lib.learning.cloud_check) and SCTDN's read-out through it."""

import numpy as np
import pytest
import torch

from skt_lib.geometry.objects import REFERENCE_RING_RADIUS_M as R, REFERENCE_SECTION_M as W
from skt_lib.geometry.skt import skt_frames
from skt_lib.learning.cloud_check import (RING_CENTRE_BELOW_M, clearest, ring_penetrations,
                                          ring_placements)
from skt_lib.learning.data import normalise
from skt_lib.learning.predictor import SktPredictor
from skt_lib.learning.sctdn import Sctdn, SctdnConfig

#: Straight into the wall along −x, ξ_0 (the hang) first: the frames are the rule's, x = −x̂,
#: z = up, so the ring's centre is RING_CENTRE_BELOW_M below each keypoint.
STRAIGHT = np.stack([0.05 + 0.01 * np.arange(5), np.zeros(5), np.zeros(5)], 1)


def _rod(z: float, radius: float = 0.003, n: int = 400) -> np.ndarray:
    """Points on a rod along x (x in 0.02…0.12) of ``radius`` with its axis at height z."""
    rng = np.random.default_rng(0)
    x = rng.uniform(0.02, 0.12, n)
    a = rng.uniform(0, 2 * np.pi, n)
    return np.stack([x, radius * np.cos(a), z + radius * np.sin(a)], 1)


def test_the_ring_hangs_below_the_keypoint_in_the_motion_plane():
    centres, axes = ring_placements(STRAIGHT, samples_per_segment=2)
    assert len(centres) == 2 * (len(STRAIGHT) - 1) + 1
    assert np.allclose(axes, [-1.0, 0.0, 0.0])
    assert np.allclose(centres[::2], STRAIGHT - [0.0, 0.0, RING_CENTRE_BELOW_M])
    assert np.allclose(centres[1::2], (STRAIGHT[:-1] + STRAIGHT[1:]) / 2 - [0, 0, RING_CENTRE_BELOW_M])
    with pytest.raises(ValueError, match="samples_per_segment"):
        ring_placements(STRAIGHT, 0)


def test_penetration_is_the_squared_depth_into_the_rings_material():
    # one point 2 mm above ξ_0's keypoint, in the ring's plane: 24 mm from the centre, so
    # 2 mm from the centreline (26 mm), 2 mm inside the 4 mm section; the next placement is
    # 10 mm along the axis, beyond the section, and sees nothing
    point = STRAIGHT[0] + [0.0, 0.0, 0.002]
    got = ring_penetrations([STRAIGHT], point[None], samples_per_segment=1)
    assert got == pytest.approx([(W - abs(RING_CENTRE_BELOW_M + 0.002 - R)) ** 2], rel=1e-9)
    # off the plane by h along the axis: distance hypot(h, 2 mm) from the centreline
    h = 0.003
    off = point + [h, 0.0, 0.0]
    want = max(W - np.hypot(h, RING_CENTRE_BELOW_M + 0.002 - R), 0.0) ** 2
    assert ring_penetrations([STRAIGHT], off[None], 1) == pytest.approx([want], rel=1e-9)


def test_a_rod_inside_the_aperture_is_clear_and_one_through_the_ring_is_not():
    inside = _rod(z=-0.005)  # just below the keypoints: in the hole, where the ring hangs
    through = _rod(z=-RING_CENTRE_BELOW_M - R)  # along the ring's bottom material
    scores = ring_penetrations([STRAIGHT, STRAIGHT], inside, 3)
    assert np.array_equal(scores, [0.0, 0.0])
    assert ring_penetrations([STRAIGHT], through, 3)[0] > 0


def test_clearest_takes_the_clear_candidate_and_the_first_of_equals():
    cloud = _rod(z=-0.005)
    lowered = STRAIGHT - [0.0, 0.0, 0.009]  # the rod (z −5 mm) cuts the ring's upper material
    assert ring_penetrations([lowered], cloud, 3)[0] > 0
    assert clearest([lowered, STRAIGHT], cloud)[0] == 1
    assert clearest([STRAIGHT, lowered], cloud)[0] == 0
    assert clearest([STRAIGHT, STRAIGHT + [0.0, 1e-4, 0.0]], cloud)[0] == 0  # equal: the first
    with pytest.raises(ValueError, match="candidates"):
        clearest([], cloud)


def _small_model(check: int) -> Sctdn:
    with torch.random.fork_rng():
        torch.manual_seed(7)
        model = Sctdn(SctdnConfig(k=3, T=8, n_points=256, check_families=check),
                      torch.randn(3, 8, 3) * 0.02)
        with torch.no_grad():  # a non-zero deformation head, so trajectory ≠ aligned
            model.offset.weight.normal_(0, 0.1)
    return model.eval()


def test_family_candidates_are_the_forward_pass_of_each_family_most_probable_first():
    model = _small_model(0)
    pts = np.random.default_rng(3).normal(size=(256, 3)) * 0.03
    xyz_n, _, s = normalise(pts)
    x, scale = torch.as_tensor(xyz_n[None], dtype=torch.float32), torch.tensor([s], dtype=torch.float32)
    with torch.no_grad():
        cand = model.family_candidates(x, scale, 3)
        assert torch.equal(cand["families"], torch.argsort(cand["logits"][0], descending=True))
        for i, f in enumerate(cand["families"]):
            one = model(x, scale, family=f[None])
            assert torch.allclose(cand["trajectory"][i], one["trajectory"][0], atol=1e-6)
            assert torch.allclose(cand["aligned"][i], one["aligned"][0], atol=1e-6)
    with pytest.raises(ValueError, match="one cloud"):
        model.family_candidates(x.expand(2, -1, -1), scale.expand(2), 3)


def test_the_checked_read_out_returns_the_candidate_clearest_of_the_cloud():
    pts = np.random.default_rng(5).normal(size=(256, 3)) * 0.03
    checked = SktPredictor(_small_model(2)).predict(pts)
    xyz_n, c, s = normalise(pts)
    model = _small_model(0)
    x, scale = torch.as_tensor(xyz_n[None], dtype=torch.float32), torch.tensor([s], dtype=torch.float32)
    with torch.no_grad():
        cand = model.family_candidates(x, scale, 2)
    options = [cand[k][i].double().numpy() * s + c for i in range(2) for k in ("trajectory", "aligned")]
    scores = ring_penetrations(options, pts)
    best = int(np.argmin(scores))
    assert best != 0 and scores[best] < scores[0]  # here the check overrules the classifier
    assert np.allclose(checked.positions, options[best])
    assert checked.family == int(cand["families"][best // 2])
    probs = torch.softmax(cand["logits"][0].double(), -1)
    assert checked.family_probability == pytest.approx(float(probs[checked.family]))
    # the returned SKT carries its own frames; the other candidates are its set-up
    # fallbacks, clearest first
    assert np.array_equal(checked.frames, skt_frames(checked.positions))
    order = [j for j in np.argsort(scores, kind="stable") if j != best]
    assert len(checked.fallbacks) == 3
    for got, j in zip(checked.fallbacks, order):
        assert np.allclose(got, options[j])
    # off: the paper's read-out, the classifier's family deformed, with no fallbacks
    plain = SktPredictor(model).predict(pts)
    assert np.allclose(plain.positions, options[0]) and plain.fallbacks == ()
    # the template-only row never runs the check
    templ = SktPredictor(_small_model(2)).predict(pts, deform=False)
    assert np.allclose(templ.positions, options[1]) and templ.fallbacks == ()


def test_given_rotations_score_as_computed_ones():
    """The read-out passes frames it already has (a template's are its stored template's);
    the scores are those of frames computed from the positions, and a wrong shape is refused."""
    cloud = _rod(z=-0.005)
    lowered = STRAIGHT - [0.0, 0.0, 0.009]
    rot = [skt_frames(c)[:, :3, :3] for c in (lowered, STRAIGHT)]
    assert np.array_equal(ring_penetrations([lowered, STRAIGHT], cloud, rotations=rot),
                          ring_penetrations([lowered, STRAIGHT], cloud))
    # the frames, not the positions, set the ring's axes: turned frames move the score
    quarter = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1.0]])
    turned = [np.einsum("ij,tjk->tik", quarter, r) for r in rot]
    assert not np.array_equal(ring_penetrations([lowered], cloud, rotations=turned[:1]),
                              ring_penetrations([lowered], cloud))
    with pytest.raises(ValueError, match="rotations"):
        ring_placements(STRAIGHT, rotations=rot[0][:-1])
    with pytest.raises(ValueError, match="one per candidate"):
        ring_penetrations([lowered, STRAIGHT], cloud, rotations=rot[:1])


def test_check_families_is_bounded_by_the_number_of_families():
    with pytest.raises(ValueError, match="check_families"):
        SctdnConfig(k=3, T=8, check_families=4)
    assert SctdnConfig.from_json('{"k": 3, "T": 8}').check_families == 0  # older checkpoints
