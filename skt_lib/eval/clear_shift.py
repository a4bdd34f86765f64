"""``skt_flow``'s last read-out step: each SKT moved, as a whole, clear of the observed points.

The cloud check (:mod:`skt_lib.learning.cloud_check`) carries the reference ring along an
SKT and measures how deep it cuts into the cloud the SKT was predicted from. It can rank
samples, but where every sample of a support cuts the visible hook — most failed supports of
validation: every sample several hundred mm² deep, all ten hung nothing — ranking cannot
help. Here the SKT is translated by the δ that minimises that penetration, the ring's
section widened by ``margin_m`` so that it stays a little off the points:

    E(δ) = Σ_{placements i, points j} max(0, (section + margin) − ρ_ij(δ))²,

``ρ_ij`` the distance of point j from the ring's centreline at placement i moved by δ (the
ring's placements and axes as :func:`~skt_lib.learning.cloud_check.ring_placements` gives
them). A translation keeps the SKT's shape and its frames' rotations (the arm follows the
same motion, elsewhere), so nothing the network learned is bent. E is minimised by
``iterations`` Adam steps of ``step_m`` (Kingma & Ba 2015; β = 0.9, 0.999) on its exact
gradient, the point pairs within reach re-found every ``requery`` steps, stopping as soon as
E is 0; no point in reach, no move. Plain numpy, no threads: the same δ on every run.

Measured on validation (``tools/val_sim.py``'s pairs: 40 supports × the 10 training objects,
every sample of the committed model hung; docs/pipeline.md): the one-SKT row 63.0 → 75.0 %
(53 pairs gained, 5 lost; +12.0 points [+4.3, +21.3] over supports), every level up; the best
of ten 70.0 → 83.5 % with every sample moved. A margin of 1 mm: 0 gave 73.8 %, 2 mm 76.5 and
3 mm 74.2 (1 kept: 2 mm's gain, 7 pairs against 1, is within chance). A smooth deformation
(six control points) instead of a translation lost as many pairs as it gained.
"""

from dataclasses import replace

import numpy as np
from scipy.spatial import cKDTree

from skt_lib.geometry.objects import REFERENCE_RING_RADIUS_M, REFERENCE_SECTION_M
from skt_lib.learning.cloud_check import ring_placements
from skt_lib.learning.predictor import Skt

MARGIN_M = 0.001
STEP_M = 0.0005
ITERATIONS = 60
REQUERY = 10
#: Points this much beyond the ring's outer radius are paired with a placement too: the ring
#: moves between re-queries.
SLACK_M = 0.003
_BETA1, _BETA2, _EPS = 0.9, 0.999, 1e-8


def clear_shift(positions: np.ndarray, cloud: np.ndarray, rotations: np.ndarray | None = None,
                margin_m: float = MARGIN_M, step_m: float = STEP_M,
                iterations: int = ITERATIONS) -> np.ndarray:
    """The translation ``(3,)`` (m) that moves the SKT ``positions (T, 3)`` (support frame, ξ_0
    first) clear of ``cloud (N, 3)``; ``rotations (T, 3, 3)``: its SKT frames' rotations where
    the caller has them. Zero when the ring, widened by ``margin_m``, cuts no point."""
    # millimetres inside: Adam's ε is an absolute scale
    centres, axes = ring_placements(positions, rotations=rotations)
    centres, pts = centres * 1000.0, np.asarray(cloud, np.float64) * 1000.0
    radius, section = REFERENCE_RING_RADIUS_M * 1000.0, (REFERENCE_SECTION_M + margin_m) * 1000.0
    tree = cKDTree(pts)
    delta, m, v = np.zeros(3), np.zeros(3), np.zeros(3)
    pi = pj = None
    for it in range(iterations):
        c = centres + delta
        if it % REQUERY == 0:
            near = tree.query_ball_point(c, radius + section + SLACK_M * 1000.0)
            pi = np.repeat(np.arange(len(c)), [len(n) for n in near])
            if not len(pi):
                break
            pj = np.concatenate([np.asarray(n, dtype=np.intp) for n in near])
        w = pts[pj] - c[pi]
        a = axes[pi]
        h = np.einsum("ij,ij->i", w, a)
        radial = w - h[:, None] * a
        r = np.linalg.norm(radial, axis=1)
        rho = np.sqrt(h * h + (r - radius) ** 2 + 1e-9)
        pen = np.maximum(section - rho, 0.0)
        if it > 0 and not pen.any():
            break
        cut = pen > 0
        # dρ/dw = (h a + (r − R) r̂) / ρ; w = p − c − δ, so dE/dδ = Σ 2 pen dρ/dw
        rhat = radial[cut] / np.maximum(r[cut], 1e-12)[:, None]
        drho = (h[cut, None] * a[cut] + (r[cut] - radius)[:, None] * rhat) / rho[cut, None]
        grad = (2.0 * pen[cut, None] * drho).sum(0)
        m = _BETA1 * m + (1 - _BETA1) * grad
        v = _BETA2 * v + (1 - _BETA2) * grad * grad
        m_hat, v_hat = m / (1 - _BETA1 ** (it + 1)), v / (1 - _BETA2 ** (it + 1))
        delta = delta - step_m * 1000.0 * m_hat / (np.sqrt(v_hat) + _EPS)
    return delta / 1000.0


def shifted(skt: Skt, cloud: np.ndarray) -> Skt:
    """``skt`` moved by :func:`clear_shift` against ``cloud`` (the points it was predicted
    from): positions and frames translated, everything else as it was."""
    delta = clear_shift(skt.positions, cloud, skt.frames[:, :3, :3])
    if not delta.any():
        return skt
    frames = skt.frames.copy()
    frames[:, :3, 3] += delta
    return replace(skt, positions=skt.positions + delta, frames=frames)
