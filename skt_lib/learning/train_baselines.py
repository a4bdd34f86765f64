"""Training and validation of the VAT-Mart baselines (:mod:`skt_lib.learning.vatmart`) and of
``skt_flow`` (:mod:`skt_lib.learning.flow`) with the loop, data and budget of SCTDN
(:func:`skt_lib.learning.train.fit`)."""

from collections.abc import Callable
from dataclasses import replace

import numpy as np
import torch

from skt_lib.coverage import coverage
from skt_lib.learning.data import SupportData, normalise
from skt_lib.learning.flow import (
    FlowConfig,
    FlowPredictor,
    SktFlow,
    control_stats,
    flow_loss,
    order_by_cloud_check,
)
from skt_lib.learning.predictor import SktPredictor
from skt_lib.learning.sctdn import SctdnConfig, traj_distance
from skt_lib.learning.train import CONTACT_OK_M, TrainSettings, fit, make_batch, train_sctdn
from skt_lib.learning.vatmart import (
    VatMart,
    VatMartConfig,
    VatMartPredictor,
    pick_targets,
    vatmart_loss,
)

#: The VAT-Mart variants: the conditioning feature of each (paper §VI-A).
CONDITION = {"vatmart": "contact_point", "vatmart_mod": "shape"}

#: Validation latents: drawn once from this seed, the same for every epoch and model, so
#: epochs are compared on the same samples.
VAL_LATENT_SEED = 0


def train_baseline(name: str, cfg: SctdnConfig, templates, train: list[SupportData],
                   val: list[SupportData], st: TrainSettings, seed: int, n_proposals: int,
                   baselines, on_epoch: Callable[[int, dict], None] | None = None
                   ) -> tuple[SktPredictor | VatMartPredictor | FlowPredictor, dict]:
    """Train baseline ``name`` with SCTDN's config ``cfg``, ``templates`` and loop:
    ``sctdn_cp_feature`` (SCTDN conditioned on the contact-point feature) or a VAT-Mart
    variant (:data:`CONDITION`, params section ``baselines``); the predictor to save and
    its best validation epoch's metrics."""
    if name == "sctdn_cp_feature":
        model, best = train_sctdn(replace(cfg, condition="contact_point"), templates, train, val,
                                  st, seed, on_epoch)
        return SktPredictor(model), best
    if name == "skt_flow":
        model, best = train_flow(flow_config(cfg, baselines, train), train, val, st, seed,
                                 n_proposals, on_epoch)
        return FlowPredictor(model), best
    model, best = train_vatmart(vatmart_config(name, cfg, baselines), train, val, st, seed,
                                n_proposals, on_epoch)
    return VatMartPredictor(model), best


@torch.no_grad()
def evaluate_vatmart(model: VatMart, supports: list[SupportData], views, n_proposals: int,
                     batch_size: int = 16) -> dict:
    """Validation figures without teacher forcing (contact = argmax affordance):
    ``val_traj_l2_mm`` (one proposal per view: the first of ``n_proposals`` fixed latents),
    ``val_best_of_n_l2_mm`` (the best of the ``n_proposals``), ``val_spread_mm`` (mean
    distance of the proposals from their mean: 0 means the CVAE ignores its latent),
    ``val_affordance_mse`` and ``val_contact_within_1cm_rate`` (visible contacts only)."""
    model.eval()
    items = [(s, int(v)) for s in supports for v in views]
    z = torch.as_tensor(np.random.default_rng(VAL_LATENT_SEED).standard_normal(
        (n_proposals, model.cfg.latent)), dtype=torch.float32)
    single, best, spread, mse, within = [], [], [], [], []
    for i in range(0, len(items), batch_size):
        chunk = items[i: i + batch_size]
        b = make_batch(chunk)
        enc = model.encode_cloud(b["xyz"])
        n = len(chunk)
        traj = model.decode(z.repeat_interleave(n, 0), enc["cond"].repeat(n_proposals, 1),
                            enc["contact"].repeat(n_proposals, 1)).view(n_proposals, n, -1, 3)
        mm = b["scale"] * 1000
        d = torch.stack([traj_distance(t, b["gt"], b["valid"]) for t in traj]) * mm  # (P, n)
        single.append(d[0])
        best.append(d.min(0).values)
        spread.append(torch.linalg.norm(traj - traj.mean(0), dim=-1).mean((0, 2)) * mm)
        mse.append(((enc["affordance"] - b["aff"]) ** 2).mean(-1))
        for j, (sup, v) in enumerate(chunk):
            if sup.contact_visible[v]:
                picked = sup.points[v][int(enc["affordance"][j].argmax())]
                within.append(float(np.linalg.norm(picked - sup.contact)) <= CONTACT_OK_M)
    mean = lambda xs: float(torch.cat(xs).double().mean())  # noqa: E731
    return {"val_traj_l2_mm": mean(single), "val_best_of_n_l2_mm": mean(best),
            "val_spread_mm": mean(spread), "val_affordance_mse": mean(mse),
            "val_contact_within_1cm_rate": float(np.mean(within)) if within else None}


def vatmart_config(name: str, sctdn: SctdnConfig, baselines) -> VatMartConfig:
    """The config of VAT-Mart variant ``name`` (:data:`CONDITION`) with SCTDN's backbone
    (``sctdn``) and the ``train_baselines`` params section ``baselines``."""
    if name not in CONDITION:
        raise ValueError(f"name: expected one of {list(CONDITION)}, got {name!r}")
    return VatMartConfig(T=sctdn.T, condition=CONDITION[name],
                         kl_weight=getattr(baselines, f"{name}_kl_weight"),
                         n_points=sctdn.n_points, latent=baselines.latent_dim,
                         hidden=baselines.hidden, feat_dim=sctdn.feat_dim,
                         aff_threshold=sctdn.aff_threshold, centres=sctdn.centres,
                         nsample=sctdn.nsample, n_control=baselines.n_control_points)


def train_vatmart(cfg: VatMartConfig, train: list[SupportData], val: list[SupportData],
                  st: TrainSettings, seed: int, n_proposals: int,
                  on_epoch: Callable[[int, dict], None] | None = None) -> tuple[VatMart, dict]:
    """Train a VAT-Mart CVAE; the best epoch is chosen on the single-proposal validation
    error (``val_traj_l2_mm``), never on training supports."""
    def batch_loss(model, b):
        target = pick_targets(b["gt"], b["valid"])
        out = model(b["xyz"], target, b["contact"])
        return vatmart_loss(out, target, b["aff"], b["contact_target"], cfg.kl_weight,
                            w_contact=st.contact_weight)

    return fit(lambda: VatMart(cfg), batch_loss,
               lambda model: evaluate_vatmart(model, val, st.val_views, n_proposals),
               train, st, seed, on_epoch)


def flow_config(sctdn: SctdnConfig, baselines, train: list[SupportData]) -> FlowConfig:
    """``skt_flow``'s config: SCTDN's backbone (``sctdn``), the ``train_baselines`` params
    section ``baselines``, and the control points' mean and spread over every view of the
    ``train`` supports (the normalised frame depends on the view)."""
    rel = [(s.skts - s.contact) / normalise(s.points[v].astype(np.float64))[2]
           for s in train for v in range(len(s.points))]
    mean, std = control_stats(np.concatenate(rel), baselines.skt_flow_n_control)
    return FlowConfig(T=sctdn.T, n_control=baselines.skt_flow_n_control,
                      steps=baselines.skt_flow_steps, draws=baselines.skt_flow_draws,
                      hidden=baselines.skt_flow_hidden, n_points=sctdn.n_points,
                      feat_dim=sctdn.feat_dim, aff_threshold=sctdn.aff_threshold,
                      centres=sctdn.centres, nsample=sctdn.nsample, ctrl_mean=mean, ctrl_std=std)


@torch.no_grad()
def evaluate_flow(model: SktFlow, supports: list[SupportData], views, n_samples: int,
                  batch_size: int = 16) -> dict:
    """Validation figures without teacher forcing (contact = argmax affordance), on
    ``n_samples`` fixed noise draws per view: ``val_traj_l2_mm`` (the sample the cloud check
    ranks first: the one SKT executed), ``val_first_l2_mm`` (the first draw, unchecked),
    ``val_best_of_n_l2_mm``, ``val_spread_mm``, ``val_coverage_1cm`` (:func:`coverage`),
    ``val_affordance_mse`` and ``val_contact_within_1cm_rate`` (visible contacts only)."""
    model.eval()
    items = [(s, int(v)) for s in supports for v in views]
    noise = torch.as_tensor(np.random.default_rng(VAL_LATENT_SEED).standard_normal(
        (n_samples, model.cfg.dim)), dtype=torch.float32)
    cols: dict[str, list] = {k: [] for k in ("checked", "first", "best", "spread", "cover",
                                             "mse")}
    within = []
    for i in range(0, len(items), batch_size):
        chunk = items[i: i + batch_size]
        b = make_batch(chunk)
        enc = model.encode_cloud(b["xyz"])
        n = len(chunk)
        traj = model.sample(noise.repeat_interleave(n, 0), enc["cond"].repeat(n_samples, 1),
                            enc["contact"].repeat(n_samples, 1)).view(n_samples, n, -1, 3)
        mm = b["scale"] * 1000
        d = torch.stack([traj_distance(t, b["gt"], b["valid"]) for t in traj]) * mm  # (P, n)
        metres = (traj.double() * b["scale"].double()[None, :, None, None]
                  + b["centroid"].double()[None, :, None]).numpy()  # (P, n, T, 3)
        for j, (sup, v) in enumerate(chunk):
            order, _ = order_by_cloud_check(metres[:, j], sup.points[v].astype(np.float64))
            cols["checked"].append(float(d[order[0], j]))
            cols["cover"].append(coverage(metres[:, j], sup.skts))
            if sup.contact_visible[v]:
                picked = sup.points[v][int(enc["affordance"][j].argmax())]
                within.append(float(np.linalg.norm(picked - sup.contact)) <= CONTACT_OK_M)
        cols["first"] += d[0].tolist()
        cols["best"] += d.min(0).values.tolist()
        cols["spread"] += (torch.linalg.norm(traj - traj.mean(0), dim=-1).mean((0, 2)) * mm).tolist()
        cols["mse"] += ((enc["affordance"] - b["aff"]) ** 2).mean(-1).tolist()
    mean = {k: float(np.mean(v)) for k, v in cols.items()}
    return {"val_traj_l2_mm": mean["checked"], "val_first_l2_mm": mean["first"],
            "val_best_of_n_l2_mm": mean["best"], "val_spread_mm": mean["spread"],
            "val_coverage_1cm": mean["cover"], "val_affordance_mse": mean["mse"],
            "val_contact_within_1cm_rate": float(np.mean(within)) if within else None}


def train_flow(cfg: FlowConfig, train: list[SupportData], val: list[SupportData],
               st: TrainSettings, seed: int, n_samples: int,
               on_epoch: Callable[[int, dict], None] | None = None) -> tuple[SktFlow, dict]:
    """Train ``skt_flow``; the best epoch is chosen on the validation error of the sample the
    cloud check picks (``val_traj_l2_mm``), never on training supports."""
    def batch_loss(model, b):
        idx = torch.multinomial(b["valid"].float(), cfg.draws, replacement=True)  # (B, D)
        target = b["gt"][torch.arange(len(idx))[:, None], idx]
        return flow_loss(model, b["xyz"], target, b["contact"], b["aff"], b["contact_target"],
                         w_contact=st.contact_weight)

    return fit(lambda: SktFlow(cfg), batch_loss,
               lambda model: evaluate_flow(model, val, st.val_views, n_samples),
               train, st, seed, on_epoch)
