"""``skt_flow``'s samples drawn from several contact hypotheses, not the affordance's argmax
alone.

The flow generates an SKT relative to the contact point it is given (at inference: the
argmax of its affordance) and conditioned on the cloud's feature there, so every sample of a
support inherits that point's error. Where the argmax lands off the hanging part — on a
knob peg's wall plate above the peg, say — all ``n`` samples cut through the plate, and
neither the cloud check's ranking nor the move clear of the points
(:mod:`skt_lib.eval.clear_shift`) can bring them back to the peg.

Here the contact hypotheses are up to ``n_contacts`` points of the cloud, greedily by
affordance: the argmax, then each next most afforded point that holds at least
``min_share`` of the argmax's affordance and lies ``spacing_m`` or more from every point
taken. Sample ``i`` (noise row ``i`` of the caller's generator, as
:meth:`~skt_lib.learning.flow.FlowPredictor.propose` draws it) starts from hypothesis
``i mod K``, so the argmax keeps the first draw and the most samples. The backbone runs once;
only the condition's contact feature and position differ between hypotheses.

The order trusts the argmax: the cloud check alone cannot tell a right contact from a wrong
one (an L-hook's right path, drawn close to the arm, scores 2,000 mm² before the move clear
of the points; a wrong one beside it 600). So the argmax's samples come first, by the check,
unless even the clearest of them cuts deep (over ``deep_m2``) and another hypothesis has a
sample that cuts nothing (``clear_m2`` or less); those come first then. With one hypothesis
this is :meth:`~skt_lib.learning.flow.FlowPredictor.propose` exactly.

Chosen on validation (``tools/val_sim.py``: 40 supports × the 10 training objects, the
committed model; docs/pipeline.md): against the argmax alone, 3 hypotheses ranked by the
check alone lost 3.0 points at one SKT [−10.0, +4.0 over supports], trusting the argmax as
above gained 2.5 [−1.7, +8.3] (18 pairs gained, 8 lost; Easy 64 → 74 %), and the best of ten
rose 85.5 → 90.5 % (+5.0 [0.0, +11.5]; 25 gained, 5 lost).
"""

from dataclasses import dataclass

import numpy as np
import torch

from skt_lib.geometry.skt import skt_frames
from skt_lib.learning.data import normalise
from skt_lib.learning.flow import FlowPredictor, order_by_cloud_check
from skt_lib.learning.predictor import Skt
from skt_lib.learning.sctdn import backbone_features, feature_at, masked_max_pool
from skt_lib.perception.pointcloud import check_cloud, farthest_point_sample



@dataclass(frozen=True)
class ContactHypotheses:
    """How many contact hypotheses, how they are picked, and when the argmax's samples yield."""

    n_contacts: int = 3
    min_share: float = 0.5  # of the argmax's affordance
    spacing_m: float = 0.01  # between hypotheses
    #: the argmax's samples cut the cloud deeply beyond this cloud-check score (m²) ...
    deep_m2: float = 100e-6
    #: ... and an other hypothesis' sample is clear at or under this one
    clear_m2: float = 1e-6


def contact_candidates(points: np.ndarray, affordance: np.ndarray,
                       h: ContactHypotheses = ContactHypotheses()) -> np.ndarray:
    """Indices into ``points (N, 3)`` of up to ``h.n_contacts`` contact hypotheses, the
    argmax of ``affordance (N,)`` first (see the module's docstring)."""
    if h.n_contacts < 1:
        raise ValueError(f"n_contacts: need at least one, got {h.n_contacts}")
    order = np.argsort(-affordance, kind="stable")
    floor = h.min_share * affordance[order[0]]
    taken = [int(order[0])]
    for i in order[1:]:
        if len(taken) == h.n_contacts or affordance[i] < floor:
            break
        if np.linalg.norm(points[taken] - points[i], axis=1).min() >= h.spacing_m:
            taken.append(int(i))
    return np.array(taken)


@torch.inference_mode()
def propose(flow: FlowPredictor, points: np.ndarray, rng: np.random.Generator, n: int,
            h: ContactHypotheses = ContactHypotheses()) -> list[Skt]:
    """``n`` SKT samples of ``flow`` for a cloud ``(N, 3)`` (support frame, metres) from up to
    ``h.n_contacts`` contact hypotheses, the clearest by the cloud check first; each
    :class:`~skt_lib.learning.predictor.Skt`'s ``contact`` is its own hypothesis."""
    if n < 1:
        raise ValueError(f"n: need at least one sample, got {n}")
    cfg = flow.cfg
    pts = check_cloud(points, "points")
    if len(pts) < cfg.n_points:
        raise ValueError(f"points: need at least {cfg.n_points}, got {len(pts)}")
    if len(pts) > cfg.n_points:
        pts = pts[farthest_point_sample(pts, cfg.n_points)]
    xyz_n, c, s = normalise(pts)
    x = torch.as_tensor(xyz_n[None], dtype=torch.float32)
    g, feats = backbone_features(flow.model, x)  # once: only the contact's part differs
    aff_t = torch.sigmoid(flow.model.aff_head(feats)[:, 0])
    aff = aff_t[0].numpy()
    idx = contact_candidates(pts, aff, h)
    k, contacts = len(idx), x[0, torch.as_tensor(idx)]
    # the condition of SktFlow.encode_cloud, one row per hypothesis
    cond = torch.cat([masked_max_pool(feats, aff_t, flow.cfg.aff_threshold).expand(k, -1),
                      feature_at(feats.expand(k, -1, -1), x.expand(k, -1, -1), contacts),
                      g.expand(k, -1), contacts], -1)
    noise = torch.as_tensor(rng.standard_normal((n, cfg.dim)), dtype=torch.float32)
    of = torch.as_tensor(np.arange(n) % len(idx))
    traj = flow.model.sample(noise, cond[of], contacts[of])
    samples = traj.double().numpy() * s + c
    frames = [skt_frames(k) for k in samples]
    _, scores = order_by_cloud_check(samples, pts, frames)
    order = np.lexsort((scores, _tiers(scores, of.numpy() > 0, h)))
    return [Skt(samples[i], frames[i], -1, pts[idx[of[i]]], aff) for i in order]


def _tiers(scores: np.ndarray, other: np.ndarray, h: ContactHypotheses) -> np.ndarray:
    """Each sample's rank class: 0 the argmax's samples scoring ``deep_m2`` or less, 1 the
    other hypotheses' clear samples (``clear_m2`` or less), 2 the argmax's deep ones, 3 the
    rest."""
    return np.where(other, np.where(scores <= h.clear_m2, 1, 3),
                    np.where(scores <= h.deep_m2, 0, 2))
