"""skt_flow's SKT moved clear of the observed points: a translation that takes the reference
ring (widened by the margin) out of the cloud, found by descent on the exact gradient."""

import numpy as np
import pytest

from skt_lib.eval.clear_shift import MARGIN_M, clear_shift, shifted
from skt_lib.geometry.objects import REFERENCE_RING_RADIUS_M, REFERENCE_SECTION_M
from skt_lib.geometry.skt import skt_frames
from skt_lib.learning.cloud_check import ring_penetrations
from skt_lib.learning.predictor import Skt

T = 40


def _rod(y: float, z: float, length: float = 0.12) -> np.ndarray:
    """Points on a 4 mm rod along x (out of the wall) at height z, across y."""
    x = np.linspace(0.0, length, 200)
    ang = np.linspace(0.0, 2 * np.pi, 12, endpoint=False)
    ring = 0.004 * np.stack([np.cos(ang), np.sin(ang)], 1)
    return np.concatenate([np.c_[x, y + ring[k, 0] + 0 * x, z + ring[k, 1] + 0 * x]
                           for k in range(len(ang))])


def _approach(z: float) -> np.ndarray:
    """An SKT that comes straight down the wall's normal (−x) at height z, ξ_0 first."""
    x = np.linspace(0.04, 0.16, T)
    return np.c_[x, np.zeros(T), np.full(T, z)]


def _widened_penetration(positions, cloud) -> float:
    """The objective's own measure: the ring's section widened by the margin."""
    import skt_lib.learning.cloud_check as cc

    section, cc.REFERENCE_SECTION_M = cc.REFERENCE_SECTION_M, REFERENCE_SECTION_M + MARGIN_M
    try:
        return float(ring_penetrations([positions], cloud)[0])
    finally:
        cc.REFERENCE_SECTION_M = section


def test_a_ring_cutting_a_rod_is_moved_off_it_by_a_few_millimetres():
    # the ring threaded on the rod with its top (the keypoint) at the rod's axis: the rod's
    # upper half cuts the ring's material
    cloud = _rod(0.0, 0.0)
    skt = _approach(0.0)
    before = ring_penetrations([skt], cloud)[0]
    delta = clear_shift(skt, cloud)
    after = skt + delta
    assert before > 0 and ring_penetrations([after], cloud)[0] == 0
    assert _widened_penetration(after, cloud) < 0.01 * _widened_penetration(skt, cloud)
    assert 0.004 < np.linalg.norm(delta) < 0.010  # off the rod (4 mm radius), not far away
    assert delta[2] > 0.004  # up: the rod inside the ring's aperture, under its top


def test_no_point_within_reach_means_no_move_and_the_same_skt_back():
    cloud = _rod(0.0, 0.0)
    skt = _approach(0.1)  # 10 cm above the rod
    assert not clear_shift(skt, cloud).any()
    s = Skt(skt, skt_frames(skt), -1, np.zeros(3), np.zeros(len(cloud)))
    assert shifted(s, cloud) is s


def test_the_shifted_skt_keeps_its_shape_and_rotations_and_repeats():
    cloud = _rod(0.0, 0.0)
    pos = _approach(0.0)
    s = Skt(pos, skt_frames(pos), 2, np.ones(3), np.arange(len(cloud), dtype=float))
    a, b = shifted(s, cloud), shifted(s, cloud)
    delta = a.positions[0] - pos[0]
    assert np.array_equal(a.positions, b.positions)  # the same bits every time
    assert np.allclose(a.positions - pos, delta, atol=1e-15)  # one translation
    assert np.array_equal(a.frames[:, :3, :3], s.frames[:, :3, :3])
    assert np.allclose(a.frames[:, :3, 3], a.positions)
    assert a.family == 2 and a.contact is s.contact and a.affordance is s.affordance


@pytest.mark.parametrize("margin", [0.0, 0.002])
def test_a_wider_margin_keeps_farther_off(margin):
    cloud = _rod(0.0, 0.0)
    skt = _approach(0.0)
    base = np.linalg.norm(clear_shift(skt, cloud))
    other = np.linalg.norm(clear_shift(skt, cloud, margin_m=margin))
    assert (other < base) if margin < MARGIN_M else (other > base)
