"""The evaluated methods, all behind ``predict(cloud) -> Skt`` (Table I rows).

- ``sctdn``: the trained SCTDN (classification, affordance, deformation).
- ``template_only``: the same network's predicted template, aligned at its predicted
  contact point, not deformed (the paper's ablation row).
- ``oracle``: a ground-truth SKT of the support (privileged: built per support).
- ``oracle_floating``: the same SKT as ``oracle``, executed by a floating hand (a kinematic
  anchor, no arm: :mod:`skt_lib.sim.execute`), to separate what the data allows from what
  the arm allows.
- ``kpam``: kPAM 2.0 style (privileged: the ground-truth hanging keypoint): a straight line
  from a pre-hang keypoint in front of the support to just above the hang.

Privileged methods ignore the cloud; they are constructed per support with its ground truth.
"""

from typing import Protocol

import numpy as np

from skt_lib.learning.predictor import Skt, SktPredictor
from skt_lib.planning.trajectory import skt_frames

LEARNED = ("template_only", "sctdn")
#: Methods executed by the floating hand; every other method uses the Panda.
FLOATING = ("oracle_floating",)


def hand_of(method: str) -> str:
    """The hand that executes ``method``'s SKTs: ``"floating"`` or ``"panda"``."""
    return "floating" if method in FLOATING else "panda"


class Method(Protocol):
    def predict(self, cloud: np.ndarray) -> Skt: ...


class Learned:
    def __init__(self, predictor: SktPredictor, deform: bool):
        self.predictor, self.deform = predictor, deform

    def predict(self, cloud: np.ndarray) -> Skt:
        return self.predictor.predict(cloud, deform=self.deform)


def _given(positions: np.ndarray, n_cloud: int) -> Skt:
    positions = np.asarray(positions, dtype=np.float64)
    return Skt(positions, skt_frames(positions), -1, positions[0].copy(), np.zeros(n_cloud, np.float32))


class Oracle:
    def __init__(self, gt_positions: np.ndarray):
        self.gt = np.asarray(gt_positions, dtype=np.float64)

    def predict(self, cloud: np.ndarray) -> Skt:
        return _given(self.gt, len(cloud))


class Kpam:
    """Straight line of ``T`` waypoints from ``target + pre_hang`` to ``target`` (ξ_0 first),
    where ``target`` is the hanging keypoint raised by ``lift`` metres: the object is released
    just above its hanging pose and drops onto the support."""

    def __init__(self, hang: np.ndarray, pre_hang: np.ndarray, lift: float, T: int):
        self.target = np.asarray(hang, float) + [0.0, 0.0, lift]
        self.pre, self.T = np.asarray(pre_hang, float), T
        if np.linalg.norm(self.pre) <= 0:
            raise ValueError("kpam_pre_hang_m: must be a non-zero offset")

    def predict(self, cloud: np.ndarray) -> Skt:
        s = np.linspace(0.0, 1.0, self.T)[:, None]
        return _given(self.target + s * self.pre, len(cloud))


def make_method(name: str, predictor: SktPredictor | None, gt_positions: np.ndarray,
                pre_hang: np.ndarray, lift: float = 0.0) -> Method:
    """The method ``name`` for one support (``gt_positions (T, 3)``, ξ_0 first)."""
    if name in LEARNED:
        if predictor is None:
            raise ValueError(f"{name}: needs the trained predictor")
        return Learned(predictor, deform=name == "sctdn")
    if name in ("oracle", "oracle_floating"):
        return Oracle(gt_positions)
    if name == "kpam":
        return Kpam(gt_positions[0], pre_hang, lift, len(gt_positions))
    raise ValueError(f"method: unknown {name!r}")
