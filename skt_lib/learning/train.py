"""The SCTDN training loop: seeded, CPU-first; best model chosen on the validation split."""

import copy
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import torch

from skt_lib.learning.data import SupportData, normalise
from skt_lib.learning.sctdn import Sctdn, SctdnConfig, sctdn_loss, traj_distance


@dataclass(frozen=True)
class TrainSettings:
    epochs: int
    views_per_epoch: int  # random views per training support per epoch
    batch_size: int
    lr: float
    weight_decay: float
    val_views: tuple[int, ...]  # fixed views of each validation support


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
    t = lambda a, dt=torch.float32: torch.as_tensor(a, dtype=dt, device=device)  # noqa: E731
    return {"xyz": t(xyz_n), "scale": t(scale), "centroid": t(c), "gt": t(gt),
            "valid": torch.as_tensor(valid, device=device),
            "aff": t(np.stack([s.affordance[v] for s, v in items])),
            "family": torch.as_tensor([s.family for s, _ in items], device=device),
            "contact": t(contact)}


@torch.no_grad()
def evaluate(model: Sctdn, supports: list[SupportData], views, batch_size: int = 16) -> dict:
    """Validation metrics in millimetres, no teacher forcing."""
    model.eval()
    items = [(s, v) for s in supports for v in views]
    traj, templ, mse, acc = [], [], [], []
    for i in range(0, len(items), batch_size):
        b = make_batch(items[i: i + batch_size])
        out = model(b["xyz"], b["scale"])
        s = b["scale"][:, None]
        traj.append(traj_distance(out["trajectory"], b["gt"], b["valid"]) * s[:, 0] * 1000)
        templ.append(traj_distance(out["aligned"], b["gt"], b["valid"]) * s[:, 0] * 1000)
        mse.append(((out["affordance"] - b["aff"]) ** 2).mean(-1))
        acc.append((out["logits"].argmax(-1) == b["family"]).float())
    cat = lambda x: float(torch.cat(x).mean())  # noqa: E731
    return {"val_traj_l2_mm": cat(traj), "val_template_only_l2_mm": cat(templ),
            "val_affordance_mse": cat(mse), "val_cls_acc": cat(acc)}


def train_sctdn(cfg: SctdnConfig, templates: np.ndarray, train: list[SupportData],
                val: list[SupportData], st: TrainSettings, seed: int,
                on_epoch: Callable[[int, dict], None] | None = None) -> tuple[Sctdn, dict]:
    """Train; returns (model with the best validation weights, its validation metrics).
    Torch's global RNG is used only inside ``fork_rng`` (nothing leaks to the caller)."""
    rng = np.random.default_rng(seed)
    with torch.random.fork_rng():
        torch.manual_seed(seed)
        model = Sctdn(cfg, torch.as_tensor(templates))
        opt = torch.optim.Adam(model.parameters(), lr=st.lr, weight_decay=st.weight_decay)
        best, best_state = None, None
        for epoch in range(st.epochs):
            model.train()
            items = [(s, int(v)) for s in train
                     for v in rng.choice(len(s.points), st.views_per_epoch, replace=False)]
            order = rng.permutation(len(items))
            losses = []
            for i in range(0, len(order), st.batch_size):
                b = make_batch([items[j] for j in order[i: i + st.batch_size]])
                out = model(b["xyz"], b["scale"], b["family"], b["contact"])
                loss, parts = sctdn_loss(out, b["gt"], b["valid"], b["aff"], b["family"])
                opt.zero_grad()
                loss.backward()
                opt.step()
                losses.append(parts | {"loss": float(loss)})
            metrics = {f"train_{k}": float(np.mean([x[k] for x in losses])) for k in losses[0]}
            metrics |= evaluate(model, val, st.val_views)
            if on_epoch:
                on_epoch(epoch, metrics)
            if best is None or metrics["val_traj_l2_mm"] < best["val_traj_l2_mm"]:
                best, best_state = metrics, copy.deepcopy(model.state_dict())
        model.load_state_dict(best_state)
    return model, best
