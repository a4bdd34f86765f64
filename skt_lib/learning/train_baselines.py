"""Training and validation of the VAT-Mart baselines (:mod:`skt_lib.learning.vatmart`) with
the loop, data and budget of SCTDN (:func:`skt_lib.learning.train.fit`)."""

from collections.abc import Callable
from dataclasses import replace

import numpy as np
import torch

from skt_lib.learning.data import SupportData
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
                   ) -> tuple[SktPredictor | VatMartPredictor, dict]:
    """Train baseline ``name`` with SCTDN's config ``cfg``, ``templates`` and loop:
    ``sctdn_cp_feature`` (SCTDN conditioned on the contact-point feature) or a VAT-Mart
    variant (:data:`CONDITION`, params section ``baselines``); the predictor to save and
    its best validation epoch's metrics."""
    if name == "sctdn_cp_feature":
        model, best = train_sctdn(replace(cfg, condition="contact_point"), templates, train, val,
                                  st, seed, on_epoch)
        return SktPredictor(model), best
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
