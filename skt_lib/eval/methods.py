"""The evaluated methods, all behind ``predict(cloud) -> Skt`` (Table I rows).

- ``sctdn``: the trained SCTDN (classification, affordance, deformation).
- ``template_only``: the same network's predicted template, placed at its predicted
  contact point (ξ_0 the model's ``release_lift_m`` above it), not deformed (the paper's
  ablation row).
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
- ``skt_flow``: conditional flow-matching samples (``train_baselines``,
  :mod:`skt_lib.learning.flow`) from ``sim_eval.flow_contacts`` contact hypotheses
  (:mod:`skt_lib.eval.contact_hypotheses`), each moved clear of the observed points
  (:mod:`skt_lib.eval.clear_shift`), then ordered by the training objects carried along
  them against those points (:mod:`skt_lib.eval.probe_check`); ``predict`` gives the
  first, the one SKT its single-SKT row executes, ``propose`` all ``n_proposals`` (its
  best-of-N row, as VAT-Mart's).
- ``omnihang``: OMPL RRT-Connect to the ground-truth hanging pose (privileged), collision
  checked against the partial cloud only (:mod:`skt_lib.eval.omnihang`).

Privileged methods use the cloud only as OmniHang does (for collision checks) or not at all;
they are constructed per support with its ground truth.
"""

from pathlib import Path
from typing import Protocol

import numpy as np

from skt_lib.errors import DataError
from skt_lib.eval import contact_hypotheses
from skt_lib.eval.contact_hypotheses import ContactHypotheses
from skt_lib.eval.clear_shift import shifted
from skt_lib.eval.probe_check import ProbeSet, ordered
from skt_lib.geometry.skt import skt_frames
from skt_lib.learning.flow import FlowPredictor
from skt_lib.learning.predictor import Skt, SktPredictor
from skt_lib.learning.vatmart import VatMartPredictor
from skt_lib.seeding import item_rng

#: Methods that need a trained model: SktPredictor ones, then the VAT-Mart proposers.
LEARNED = ("template_only", "sctdn", "sctdn_cp_feature")
PROPOSING = ("vatmart", "vatmart_mod", "skt_flow")
#: Which trained model a learned method runs (``data/train`` or ``data/train_baselines/<name>``).
MODEL_OF = {"template_only": "sctdn", "sctdn": "sctdn", "sctdn_cp_feature": "sctdn_cp_feature",
            "vatmart": "vatmart", "vatmart_mod": "vatmart_mod", "skt_flow": "skt_flow"}
#: The predictor class of each trained model (:data:`MODEL_OF`'s values).
PREDICTOR_OF = {"sctdn": SktPredictor, "sctdn_cp_feature": SktPredictor,
                "vatmart": VatMartPredictor, "vatmart_mod": VatMartPredictor,
                "skt_flow": FlowPredictor}
#: Methods built from the support's ground truth (privileged): the oracles follow a stored SKT,
#: kpam and omnihang aim at its hang (ξ_0). No ground truth, no such method.
PRIVILEGED = ("oracle", "oracle_floating", "kpam", "omnihang")
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
    """A proposing model (VAT-Mart, skt_flow): ``propose`` returns ``n`` SKTs drawn with
    ``rng`` (pass a fresh per-support generator: the proposals are then a function of the
    support); ``predict`` the first of them. ``clear``: each SKT then moved clear of the
    cloud (:func:`~skt_lib.eval.clear_shift.shifted`; skt_flow's read-out). ``contacts``:
    skt_flow's contact hypotheses
    (:class:`~skt_lib.eval.contact_hypotheses.ContactHypotheses`; None: the model's own
    ``propose``, from the affordance's argmax). ``probes``: ``draws`` SKTs (at least ``n``)
    are drawn and, moved or not, ordered by the training objects carried along them
    (:func:`~skt_lib.eval.probe_check.order_by_probes`), and the first ``n`` proposed
    (skt_flow's read-out); without probes ``draws`` is ``n``, in the model's order."""

    def __init__(self, predictor, rng: np.random.Generator, n: int, clear: bool = False,
                 contacts: ContactHypotheses | None = None, probes: ProbeSet | None = None,
                 draws: int | None = None):
        if draws is not None and draws < n:
            raise ValueError(f"draws: need at least the {n} proposals, got {draws}")
        self.predictor, self.n, self.clear, self.contacts = predictor, n, clear, contacts
        self.probes = probes
        self.draws = n if probes is None or draws is None else draws
        self.state = rng.bit_generator.state

    def propose(self, cloud: np.ndarray) -> list[Skt]:
        rng = np.random.Generator(np.random.PCG64())
        rng.bit_generator.state = self.state  # the same draws on every call
        if self.contacts is None:
            skts = self.predictor.propose(cloud, rng, self.draws)
        else:
            skts = contact_hypotheses.propose(self.predictor, cloud, rng, self.draws,
                                              self.contacts)
        if self.clear:
            skts = [shifted(k, cloud) for k in skts]
        return skts if self.probes is None else ordered(skts, cloud, self.probes)[:self.n]

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
                omnihang: tuple | None = None, flow_contacts: int = 1,
                probes: ProbeSet | None = None, flow_samples: int | None = None) -> Method:
    """The method ``name`` for one support (``gt_positions (T, 3)``, ξ_0 first).

    ``predictor``: the trained model of learned methods (:data:`MODEL_OF`); ``rng`` and
    ``n_proposals``: the proposers' latent draws; ``omnihang``: ``(object_points,
    OmniHangSettings, seed)``; ``flow_contacts``: skt_flow's contact hypotheses (1: the
    affordance's argmax alone); ``probes``: the training objects skt_flow's samples are
    ordered by (:mod:`skt_lib.eval.probe_check`; None: the cloud check's order);
    ``flow_samples``: how many it draws for them to order (default ``n_proposals``)."""
    if name in LEARNED or name in PROPOSING:
        if predictor is None:
            raise ValueError(f"{name}: needs the trained predictor")
        if name in PROPOSING:
            if rng is None:
                raise ValueError(f"{name}: needs a generator for its latents")
            if name == "skt_flow":
                return Proposals(predictor, rng, n_proposals, clear=True,
                                 contacts=ContactHypotheses(flow_contacts), probes=probes,
                                 draws=flow_samples)
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


def method_for(name: str, support_id: str, gt_positions: np.ndarray | None, params,
               models: dict, omni_points: np.ndarray | None = None,
               n_proposals: int | None = None, probes: ProbeSet | None = None) -> Method:
    """The method ``name`` for one support as ``sim_eval`` builds it: the proposers' latents
    and omnihang's planner seed from ``item_rng(common.seed, "sim_eval/<name>", support_id)``,
    so a support's SKTs are the same wherever they are made (``skt hang`` too).

    ``gt_positions (T, 3)``: the support's ground truth (None: only for methods outside
    :data:`PRIVILEGED`); ``models``: :func:`load_models`'s; ``omni_points``: the reference
    object's surface samples (:func:`~skt_lib.eval.protocol.reference_points`; omnihang only);
    ``n_proposals``: the proposers' count (default ``sim_eval.n_proposals``; the first ``k``
    proposals do not depend on it, but skt_flow's ``probes`` order all of them);
    ``probes``: skt_flow's (:func:`~skt_lib.eval.probe_check.load_probes` of the data
    root)."""
    from skt_lib.eval.omnihang import OmniHangSettings

    if gt_positions is None and name in PRIVILEGED:
        raise ValueError(f"{name}: privileged, needs the support's ground-truth SKT")
    p = params.sim_eval
    rng = item_rng(params.common.seed, f"sim_eval/{name}", support_id)
    omni = None
    if name == "omnihang":
        settings = OmniHangSettings(
            start_offset_m=(float(np.mean(params.rrt_skts.start_dx_m)), 0.0,
                            float(np.mean(params.rrt_skts.start_dz_m))),
            max_checks=p.omnihang_max_checks)
        omni = (omni_points, settings, int(rng.integers(2**31)))
    return make_method(name, models.get(MODEL_OF.get(name)), gt_positions,
                       np.asarray(p.kpam_pre_hang_m, float), p.kpam_lift_m, rng=rng,
                       n_proposals=n_proposals or p.n_proposals, omnihang=omni,
                       flow_contacts=p.flow_contacts, probes=probes,
                       flow_samples=max(p.flow_samples, n_proposals or p.n_proposals))


def model_dir(root: Path, method: str) -> Path:
    """Where the trained model of learned ``method`` lives under the data root ``root``:
    ``train/`` (SCTDN) or ``train_baselines/<model>/``."""
    name = MODEL_OF[method]
    return root / "train" if name == "sctdn" else root / "train_baselines" / name


def load_model(method: str, d: Path, T: int):
    """The trained model of learned ``method`` from the folder ``d``; :class:`DataError` if it
    cannot be loaded or predicts other than ``T`` waypoints."""
    model = PREDICTOR_OF[MODEL_OF[method]].load(d)
    if model.cfg.T != T:
        raise DataError(f"{d}: model predicts T = {model.cfg.T}, clustering.T is {T}")
    return model


def load_models(root: Path, methods, T: int) -> dict:
    """The trained models the ``methods`` need, by :data:`MODEL_OF` name."""
    models = {}
    for m in methods:
        if m in MODEL_OF and MODEL_OF[m] not in models:
            models[MODEL_OF[m]] = load_model(m, model_dir(root, m), T)
    return models
