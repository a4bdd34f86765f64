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
- ``sctdn_cp_feature``: the Table II ablation, SCTDN deforming on the contact-point feature
  (``train_baselines``).
- ``vatmart`` / ``vatmart_mod``: CVAE proposals (``train_baselines``); ``propose`` gives
  ``n_proposals`` SKTs (the paper counts a trial as hung if any of them hangs), ``predict``
  the first of them (the honest single-sample rate).
- ``omnihang``: OMPL RRT-Connect to the ground-truth hanging pose (privileged), collision
  checked against the partial cloud only (:mod:`skt_lib.eval.omnihang`).

Privileged methods use the cloud only as OmniHang does (for collision checks) or not at all;
they are constructed per support with its ground truth.
"""

from pathlib import Path
from typing import Protocol

import numpy as np

from skt_lib.errors import DataError
from skt_lib.geometry.skt import skt_frames
from skt_lib.learning.predictor import Skt, SktPredictor
from skt_lib.learning.vatmart import VatMartPredictor

#: Methods that need a trained model: SktPredictor ones, then the VAT-Mart proposers.
LEARNED = ("template_only", "sctdn", "sctdn_cp_feature")
PROPOSING = ("vatmart", "vatmart_mod")
#: Which trained model a learned method runs (``data/train`` or ``data/train_baselines/<name>``).
MODEL_OF = {"template_only": "sctdn", "sctdn": "sctdn", "sctdn_cp_feature": "sctdn_cp_feature",
            "vatmart": "vatmart", "vatmart_mod": "vatmart_mod"}
#: Methods executed by the floating hand; every other method uses the Panda.
FLOATING = ("oracle_floating",)
#: Methods whose set-up chooses among the support's stored (ground-truth) SKTs: the first
#: along which the object sweeps clear (else the one it penetrates least) and (Panda) a grasp
#: follows
#: (:attr:`~skt_lib.sim.execute.TrialTask.alternatives`).
FALLS_BACK_TO_STORED = ("oracle", "oracle_floating")


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


class Proposals:
    """A proposing model (VAT-Mart): ``propose`` returns ``n`` SKTs drawn with ``rng`` (pass a
    fresh per-support generator: the proposals are then a function of the support);
    ``predict`` the first of them."""

    def __init__(self, predictor, rng: np.random.Generator, n: int):
        self.predictor, self.n = predictor, n
        self.state = rng.bit_generator.state

    def propose(self, cloud: np.ndarray) -> list[Skt]:
        rng = np.random.Generator(np.random.PCG64())
        rng.bit_generator.state = self.state  # the same draws on every call
        return self.predictor.propose(cloud, rng, self.n)

    def predict(self, cloud: np.ndarray) -> Skt:
        return self.propose(cloud)[0]


class OmniHang:
    """RRT-Connect (OMPL) from in front of the support to the ground-truth hanging frame
    ``hang (4, 4)``, the object (``object_points`` in its keypoint frame) checked against the
    cloud; ``T`` waypoints. ``last`` keeps the last plan (``solved``, ``seconds``)."""

    def __init__(self, hang: np.ndarray, object_points: np.ndarray, settings, seed: int, T: int):
        self.hang, self.points, self.settings, self.seed, self.T = hang, object_points, settings, seed, T
        self.last = None

    def predict(self, cloud: np.ndarray) -> Skt:
        from skt_lib.eval.omnihang import plan_omnihang

        self.last = plan_omnihang(cloud, self.hang, self.points, self.T, self.settings, self.seed)
        return _given(self.last.positions, len(cloud))


def make_method(name: str, predictor, gt_positions: np.ndarray, pre_hang: np.ndarray,
                lift: float = 0.0, rng: np.random.Generator | None = None, n_proposals: int = 1,
                omnihang: tuple | None = None) -> Method:
    """The method ``name`` for one support (``gt_positions (T, 3)``, ξ_0 first).

    ``predictor``: the trained model of learned methods (:data:`MODEL_OF`); ``rng`` and
    ``n_proposals``: the proposers' latent draws; ``omnihang``: ``(object_points,
    OmniHangSettings, seed)``."""
    if name in LEARNED or name in PROPOSING:
        if predictor is None:
            raise ValueError(f"{name}: needs the trained predictor")
        if name in PROPOSING:
            if rng is None:
                raise ValueError(f"{name}: needs a generator for its latents")
            return Proposals(predictor, rng, n_proposals)
        return Learned(predictor, deform=name != "template_only")
    if name == "omnihang":
        if omnihang is None:
            raise ValueError("omnihang: needs (object points, settings, seed)")
        return OmniHang(skt_frames(np.asarray(gt_positions, float))[0], *omnihang, len(gt_positions))
    if name in ("oracle", "oracle_floating"):
        return Oracle(gt_positions)
    if name == "kpam":
        return Kpam(gt_positions[0], pre_hang, lift, len(gt_positions))
    raise ValueError(f"method: unknown {name!r}")


def load_models(root: Path, methods, T: int) -> dict:
    """The trained models the ``methods`` need, by :data:`MODEL_OF` name."""
    models = {}
    for name in dict.fromkeys(MODEL_OF[m] for m in methods if m in MODEL_OF):
        d = root / "train" if name == "sctdn" else root / "train_baselines" / name
        model = (VatMartPredictor if name in PROPOSING else SktPredictor).load(d)
        if model.cfg.T != T:
            raise DataError(f"{d}: model predicts T = {model.cfg.T}, clustering.T is {T}")
        models[name] = model
    return models
