"""Multimodality coverage (issue 53): how many of a support's ground-truth SKTs a method's
samples reach.

A support's SKTs are its modes — different start regions, the same hang — and a method that
samples (VAT-Mart's CVAE, ``skt_flow``'s flow) is meant to carry them. For one support the
coverage is the share of its ground-truth SKTs that at least one of the method's first ``n``
samples comes within :data:`COVER_M` of, by mean waypoint distance (the distance the
training losses and ``val_traj_l2_mm`` use). A single-SKT method reaches at most one mode.
"""

import numpy as np

from skt_lib.config import LEVELS

#: A sample within this mean waypoint distance (m) of a ground-truth SKT covers it.
COVER_M = 0.01


def coverage(samples: np.ndarray, gt: np.ndarray, within_m: float = COVER_M) -> float:
    """The share of the ground-truth SKTs ``gt (G, T, 3)`` that some of ``samples (n, T, 3)``
    comes within ``within_m`` of (mean waypoint distance, metres): 1 when the samples reach
    every SKT of the support, ``1/G`` when they all sit on one of ``G`` distinct ones."""
    samples, gt = np.asarray(samples, float), np.asarray(gt, float)
    if samples.ndim != 3 or gt.ndim != 3 or samples.shape[1:] != gt.shape[1:] or not len(gt) \
            or not len(samples):
        raise ValueError(f"samples, gt: need (n ≥ 1, T, 3) and (G ≥ 1, T, 3), got {samples.shape} "
                         f"and {gt.shape}")
    d = np.linalg.norm(samples[:, None] - gt[None], axis=-1).mean(-1)  # (n, G)
    return float((d.min(0) <= within_m).mean())


def multimodality_coverage(positions: dict, supports, methods, n: int) -> dict:
    """Per method, the mean over test supports of :func:`coverage` of its first ``n`` SKTs
    (``positions[(method, support_id)]``, a list of ``(T, 3)``) against the support's stored
    SKTs (``gt`` and ``others``): ``{method: {"all": …, <level>: … or None, "n_samples":
    the most SKTs the method gave a support}}``. Supports without ground truth are skipped."""
    out = {}
    for m in methods:
        per = [(s.difficulty, coverage(positions[m, s.support_id][:n], [s.gt, *s.others]))
               for s in supports if s.gt is not None]
        by = {lv: [c for d, c in per if d == lv] for lv in LEVELS}
        out[m] = {"all": float(np.mean([c for _, c in per])) if per else None,
                  **{lv: float(np.mean(v)) if v else None for lv, v in by.items()},
                  "n_samples": max(min(len(positions[m, s.support_id]), n) for s in supports)}
    return out
