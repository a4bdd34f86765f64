"""The SCTDN training loop: seeded, CPU-first; best model chosen on the validation split."""

import copy
from collections.abc import Callable
from contextlib import contextmanager
from dataclasses import dataclass, replace

import numpy as np
import torch

from skt_lib.learning.data import SupportData, normalise
from skt_lib.learning.pointnet2 import geometry_memo
from skt_lib.learning.sctdn import Sctdn, SctdnConfig, sctdn_loss, traj_distance
from skt_lib.stats import bootstrap_mean_interval, wilson_interval


@dataclass(frozen=True)
class TrainSettings:
    epochs: int
    views_per_epoch: int  # random views per training support per epoch
    batch_size: int
    lr: float
    lr_final_ratio: float  # cosine decay over the epochs down to lr × this
    weight_decay: float
    val_views: tuple[int, ...]  # fixed views of each validation support
    contact_weight: float  # weight of the contact cross-entropy (sctdn_loss w_contact)
    threads: int = 2  # torch CPU threads: float sums depend on it (see reproducible())


def from_params(p, k: int, T: int, n_points: int) -> tuple[SctdnConfig, TrainSettings]:
    """The model config and loop settings of a ``train`` params section (TrainParams)."""
    cfg = SctdnConfig(k=k, T=T, n_points=n_points, feat_dim=p.feat_dim, lstm_hidden=p.lstm_hidden,
                      centres=p.centres, nsample=p.nsample, hang_taper=p.hang_taper_waypoints,
                      check_families=p.check_families)
    return cfg, TrainSettings(p.epochs, p.views_per_epoch, p.batch_size, p.lr, p.lr_final_ratio,
                              p.weight_decay, tuple(p.val_views), p.contact_weight, p.threads)


def make_batch(items: list[tuple[SupportData, int]], device="cpu"):
    """Tensors for (support, view) pairs; ground truth in each cloud's normalised frame."""
    pts = np.stack([s.points[v] for s, v in items]).astype(np.float64)
    xyz_n, c, scale = normalise(pts)
    g = max(len(s.skts) for s, _ in items)
    gt = np.zeros((len(items), g) + items[0][0].skts.shape[1:])
    valid = np.zeros((len(items), g), bool)
    for i, (s, _) in enumerate(items):
        gt[i, : len(s.skts)] = (s.skts - c[i]) / scale[i]
        valid[i, : len(s.skts)] = True
    contact = np.stack([(s.contact - c[i]) / scale[i] for i, (s, _) in enumerate(items)])
    cp = np.stack([s.contact_map[v] for s, v in items]).astype(np.float64)
    t = lambda a, dt=torch.float32: torch.as_tensor(a, dtype=dt, device=device)  # noqa: E731
    return {"xyz": t(xyz_n), "scale": t(scale), "centroid": t(c), "gt": t(gt),
            "valid": torch.as_tensor(valid, device=device),
            "aff": t(np.stack([s.affordance[v] for s, v in items])),
            "family": torch.as_tensor([s.family for s, _ in items], device=device),
            "contact": t(contact),
            # the view's contact map M_cp as a distribution over its points: the contact
            # cross-entropy's target, peaked at the point nearest the contact
            "contact_target": t(cp / cp.sum(-1, keepdims=True))}


#: A predicted contact (argmax affordance) within this of the true one counts as right.
CONTACT_OK_M = 0.01


@torch.no_grad()
def predict_items(model: Sctdn, items: list[tuple[SupportData, int]], batch_size: int = 16) -> dict:
    """Per (support, view) figures, no teacher forcing: ``traj_mm`` and ``template_mm``
    (mean waypoint distance to the nearest ground-truth SKT), ``aff_mse``, ``cls_ok``,
    ``contact_err_m`` (argmax-affordance point to the true contact), ``contact_visible``
    (as stored by affordance_maps): arrays
    ``(len(items),)``; ``trajectory_m``, ``aligned_m`` ``(len(items), T, 3)`` and ``contact_m``
    ``(len(items), 3)``: the prediction in metres, support frame."""
    model.eval()
    cols: dict[str, list] = {k: [] for k in ("traj_mm", "template_mm", "aff_mse", "cls_ok",
                                             "contact_err_m", "contact_visible", "trajectory_m",
                                             "aligned_m", "contact_m")}
    for i in range(0, len(items), batch_size):
        chunk = items[i: i + batch_size]
        b = make_batch(chunk)
        out = model(b["xyz"], b["scale"])
        s = b["scale"]
        cols["traj_mm"].append(traj_distance(out["trajectory"], b["gt"], b["valid"]) * s * 1000)
        cols["template_mm"].append(traj_distance(out["aligned"], b["gt"], b["valid"]) * s * 1000)
        cols["aff_mse"].append(((out["affordance"] - b["aff"]) ** 2).mean(-1))
        cols["cls_ok"].append((out["logits"].argmax(-1) == b["family"]).float())
        to_m = lambda x: (x.double() * s[:, None, None] + b["centroid"][:, None]).numpy()  # noqa: E731
        cols["trajectory_m"].extend(to_m(out["trajectory"]))
        cols["aligned_m"].extend(to_m(out["aligned"]))
        for j, (sup, v) in enumerate(chunk):
            pts = sup.points[v].astype(np.float64)
            picked = pts[int(out["affordance"][j].argmax())]
            cols["contact_m"].append(picked)
            cols["contact_err_m"].append(float(np.linalg.norm(picked - sup.contact)))
            cols["contact_visible"].append(bool(sup.contact_visible[v]))
    return {k: (torch.cat(v).double().numpy() if isinstance(v[0], torch.Tensor) else np.asarray(v))
            for k, v in cols.items()}


def summarise(per_item: dict) -> dict:
    """Validation metrics (mm, fractions) from :func:`predict_items`' arrays."""
    visible = per_item["contact_visible"]
    within = per_item["contact_err_m"][visible] <= CONTACT_OK_M
    return {"val_traj_l2_mm": float(per_item["traj_mm"].mean()),
            "val_template_only_l2_mm": float(per_item["template_mm"].mean()),
            "val_affordance_mse": float(per_item["aff_mse"].mean()),
            "val_cls_acc": float(per_item["cls_ok"].mean()),
            # None (JSON null) when no view shows the contact: no rate to report
            "val_contact_within_1cm_rate": float(within.mean()) if visible.any() else None}


def intervals(per_item: dict, support_ids, rng: np.random.Generator) -> dict:
    """95 % intervals of :func:`summarise`'s figures, as ``<metric>_ci95: [lo, hi]`` (or
    ``None`` where the metric has no items): Wilson over the (support, view) items for the two
    rates, a bootstrap over supports for the mean errors (a support's views are not
    independent: whole supports are resampled). ``support_ids (n,)`` names each item's
    support."""
    support_ids = np.asarray(support_ids)
    visible = per_item["contact_visible"]
    within = per_item["contact_err_m"][visible] <= CONTACT_OK_M
    out = {}
    for name, flags in (("val_cls_acc", per_item["cls_ok"] > 0.5),
                        ("val_contact_within_1cm_rate", within)):
        ci = wilson_interval(int(flags.sum()), len(flags))
        out[f"{name}_ci95"] = None if ci is None else list(ci)
    for name, key in (("val_traj_l2_mm", "traj_mm"), ("val_template_only_l2_mm", "template_mm"),
                      ("val_affordance_mse", "aff_mse")):
        ci = bootstrap_mean_interval(per_item[key], support_ids, rng)
        out[f"{name}_ci95"] = None if ci is None else list(ci)
    return out


def evaluate(model: Sctdn, supports: list[SupportData], views, batch_size: int = 16) -> dict:
    """Validation metrics over every support × ``views``."""
    return summarise(predict_items(model, [(s, int(v)) for s in supports for v in views], batch_size))


@contextmanager
def reproducible(threads: int):
    """Deterministic torch kernels and a fixed intra-op thread count for the block (both are
    restored after): the same seed then gives the same weights, bit for bit, on any machine
    with the same CPU instruction set, whatever its core count."""
    old_threads, old_det = torch.get_num_threads(), torch.are_deterministic_algorithms_enabled()
    torch.set_num_threads(threads)
    torch.use_deterministic_algorithms(True)
    try:
        yield
    finally:
        torch.set_num_threads(old_threads)
        torch.use_deterministic_algorithms(old_det)


def fit(make_model: Callable[[], torch.nn.Module], batch_loss, validate, train: list[SupportData],
        st: TrainSettings, seed: int, on_epoch: Callable[[int, dict], None] | None = None,
        select: str = "val_traj_l2_mm") -> tuple[torch.nn.Module, dict]:
    """The training loop shared by SCTDN and the baselines: Adam + cosine decay over
    ``st.epochs``; each epoch draws ``st.views_per_epoch`` random views of every training
    support and steps on ``batch_loss(model, batch) -> (loss, {part: float})``; then
    ``validate(model) -> metrics`` and keeps the weights with the lowest ``metrics[select]``.
    Returns (model with those weights, their metrics). Torch's global RNG is used only inside
    ``fork_rng`` (nothing leaks to the caller); ``make_model`` runs right after it is seeded.
    Sampling and neighbour searches are kept per cloud (:func:`geometry_memo`; inside an outer
    one, e.g. several models on the same views, they are shared): a view drawn again is not
    searched again."""
    rng = np.random.default_rng(seed)
    with torch.random.fork_rng(), reproducible(st.threads), geometry_memo():
        torch.manual_seed(seed)
        model = make_model()
        opt = torch.optim.Adam(model.parameters(), lr=st.lr, weight_decay=st.weight_decay)
        sched = torch.optim.lr_scheduler.CosineAnnealingLR(
            opt, T_max=max(st.epochs - 1, 1), eta_min=st.lr * st.lr_final_ratio)
        best, best_state = None, None
        for epoch in range(st.epochs):
            model.train()
            items = [(s, int(v)) for s in train
                     for v in rng.choice(len(s.points), st.views_per_epoch, replace=False)]
            order = rng.permutation(len(items))
            losses = []
            for i in range(0, len(order), st.batch_size):
                batch = make_batch([items[j] for j in order[i: i + st.batch_size]])
                loss, parts = batch_loss(model, batch)
                opt.zero_grad()
                loss.backward()
                opt.step()
                losses.append(parts | {"loss": loss.item()})
            sched.step()
            metrics = {f"train_{k}": float(np.mean([x[k] for x in losses])) for k in losses[0]}
            metrics |= validate(model)
            if on_epoch:
                on_epoch(epoch, metrics)
            if best is None or metrics[select] < best[select]:
                best, best_state = metrics, copy.deepcopy(model.state_dict())
        model.load_state_dict(best_state)
    return model, best


def release_lift(supports: list[SupportData]) -> float:
    """How far above the support's contact point an SKT's ξ_0 sits (m): the mean over
    ``supports`` of each one's mean over its SKTs of (ξ_0 − contact)·z, so every support
    counts once. ξ_0 is the reference's keypoint at the release — its aperture's top, clear
    of the arm and lifted where the planner had to (``rrt_skts.max_release_offset_m``) —
    while the contact is the point of the arm it rests on; the template, stored relative to
    ξ_0, is placed this far above the predicted contact. Only the vertical part: the
    horizontal offset is the reference ring's own tilt at the hang (~2.6 mm to one side),
    which other objects do not share."""
    if not supports:
        raise ValueError("supports: need at least one to estimate the release lift")
    return float(np.mean([np.mean(s.skts[:, 0, 2] - s.contact[2]) for s in supports]))


def train_sctdn(cfg: SctdnConfig, templates: np.ndarray, train: list[SupportData],
                val: list[SupportData], st: TrainSettings, seed: int,
                on_epoch: Callable[[int, dict], None] | None = None) -> tuple[Sctdn, dict]:
    """Train SCTDN (or its ablation, ``cfg.condition``) with its templates placed
    :func:`release_lift` (of ``train``) above the contact; returns (model with the best
    validation weights, its validation metrics)."""
    cfg = replace(cfg, release_lift_m=release_lift(train))
    def batch_loss(model, b):
        out = model(b["xyz"], b["scale"], b["family"], b["contact"])
        return sctdn_loss(out, b["gt"], b["valid"], b["aff"], b["family"], b["contact_target"],
                          w_contact=st.contact_weight)

    return fit(lambda: Sctdn(cfg, torch.as_tensor(templates)), batch_loss,
               lambda model: evaluate(model, val, st.val_views), train, st, seed, on_epoch)
