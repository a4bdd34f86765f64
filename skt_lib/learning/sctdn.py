"""SCTDN (paper §V-B): classify the support's template family, predict its affordance map,
align the family's template at the predicted contact point and deform it with
shape-conditioned features. Deviation: the template's ξ_0 goes ``release_lift_m`` above the
contact point, not onto it (the training SKTs' mean; see :class:`SctdnConfig`).

Inputs are normalised clouds: ``xyz_n = (xyz − centroid) / scale`` with ``scale`` the max
point radius, per cloud. Templates are stored in metres relative to ξ_0 and scaled into
each cloud's normalised frame. Deviation from the paper: classification and segmentation
share one PointNet++ encoder (the global feature feeds the classifier) — half the compute.

``condition`` picks the feature the deformation is conditioned on (paper Table II):
``"shape"`` (full SCTDN: max-pool of the per-point features where the affordance exceeds
``aff_threshold``) or ``"contact_point"`` (the ablation: the per-point feature at the contact
point only).
"""

import json
from dataclasses import asdict, dataclass

import torch
from torch import nn
from torch.nn import functional as F

from skt_lib.learning.pointnet2 import FeaturePropagation, SetAbstraction

CONDITIONS = ("shape", "contact_point")


@dataclass(frozen=True)
class SctdnConfig:
    k: int
    T: int
    n_points: int = 1000
    feat_dim: int = 64
    lstm_hidden: int = 64
    aff_threshold: float = 0.1
    centres: tuple[int, int, int] | None = None  # set-abstraction centres per level (None: N/4, N/16, N/64)
    nsample: int = 16  # neighbours grouped per centre
    condition: str = "shape"  # "shape" | "contact_point": the deformation's conditioning feature
    # waypoints over which the deformation fades in from the hang: offset i is scaled by
    # min(1, i / hang_taper), so ξ_0 stays where the template puts it, release_lift_m above
    # the contact (0: no taper, the paper's)
    hang_taper: int = 0
    # read-out (not in the paper): 0 returns the classifier's family, deformed; n ≥ 1 offers
    # the deformed SKT and the aligned template of each of the n most probable families and
    # returns the one the input cloud says is clearest (skt_lib.learning.cloud_check)
    check_families: int = 0
    # how far above the contact point the template's ξ_0 is placed (m, support-frame z): an
    # SKT's ξ_0 is the object's keypoint at the release, which sits above the support's
    # contact (the aperture's top clears the arm; the release may be lifted). Set from the
    # training SKTs by train_sctdn (skt_lib.learning.train.release_lift); 0: at the contact
    # (the paper's alignment)
    release_lift_m: float = 0.0

    def __post_init__(self):
        if self.condition not in CONDITIONS:
            raise ValueError(f"condition: expected one of {CONDITIONS}, got {self.condition!r}")
        if not 0 <= self.check_families <= self.k:
            raise ValueError(f"check_families: need 0 ≤ check_families ≤ k = {self.k}, "
                             f"got {self.check_families}")
        if not abs(self.release_lift_m) <= 0.02:  # a keypoint 2 cm off its contact does not rest on it
            raise ValueError(f"release_lift_m: need |release_lift_m| ≤ 0.02 m, got {self.release_lift_m}")
        if not 0 <= self.hang_taper < self.T:
            raise ValueError(f"hang_taper: need 0 ≤ hang_taper < T = {self.T}, got {self.hang_taper}")
        n = self.n_points
        centres = self.centres or (max(n // 4, 3), max(n // 16, 3), max(n // 64, 3))
        object.__setattr__(self, "centres", tuple(int(c) for c in centres))
        if not self.n_points >= self.centres[0] >= self.centres[1] >= self.centres[2] >= 3:
            raise ValueError(f"centres: need n_points ≥ c1 ≥ c2 ≥ c3 ≥ 3, got {self.centres} "
                             f"for n_points {self.n_points}")

    def to_json(self) -> str:
        return json.dumps(asdict(self), indent=2, sort_keys=True)

    @classmethod
    def from_json(cls, text: str) -> "SctdnConfig":
        data = json.loads(text)
        data.setdefault("hang_taper", 0)  # models saved before the taper deform every waypoint
        data.setdefault("check_families", 0)  # and before the cloud check read out the argmax
        data.setdefault("release_lift_m", 0.0)  # and before templates were lifted off the contact
        return cls(**data)


class Sctdn(nn.Module):
    def __init__(self, cfg: SctdnConfig, templates: torch.Tensor):
        super().__init__()
        if tuple(templates.shape) != (cfg.k, cfg.T, 3):
            raise ValueError(f"templates: expected ({cfg.k}, {cfg.T}, 3), got {tuple(templates.shape)}")
        self.cfg = cfg
        self.register_buffer("templates", templates.float())  # metres, relative to ξ_0
        add_backbone(self, cfg.centres, cfg.nsample, cfg.feat_dim)
        self.cls_head = nn.Sequential(nn.Linear(256, 128), nn.ReLU(), nn.Dropout(0.3), nn.Linear(128, cfg.k))
        self.aff_head = nn.Conv1d(cfg.feat_dim, 1, 1)
        self.wp_mlp = nn.Sequential(nn.Linear(3, 64), nn.ReLU(), nn.Linear(64, 32), nn.ReLU(),
                                    nn.Linear(32, 32))
        self.lstm = nn.LSTM(32 + cfg.feat_dim, cfg.lstm_hidden, num_layers=2, batch_first=True)
        self.offset = nn.Linear(cfg.lstm_hidden, 3)
        nn.init.zeros_(self.offset.weight)  # start as the aligned template: deform from there
        nn.init.zeros_(self.offset.bias)
        ramp = torch.clamp(torch.arange(cfg.T, dtype=torch.float32) / max(cfg.hang_taper, 1), max=1.0)
        self.register_buffer("taper", ramp[None, :, None], persistent=False)

    def forward(self, xyz_n, scale, family=None, contact_n=None) -> dict[str, torch.Tensor]:
        """``xyz_n (B, N, 3)``, ``scale (B,)``; ``family (B,)`` and ``contact_n (B, 3)`` given
        during training (teacher forcing), predicted when ``None``."""
        g, feats = backbone_features(self, xyz_n)
        logits = self.cls_head(g)
        aff_logits = self.aff_head(feats)[:, 0]  # (B, N)
        aff = torch.sigmoid(aff_logits)
        if family is None:
            family = logits.argmax(-1)
        if contact_n is None:
            contact_n = xyz_n[torch.arange(len(xyz_n)), aff.argmax(-1)]
        aligned, traj = self._deform(xyz_n, scale, feats, aff, family, contact_n)
        return {"logits": logits, "affordance": aff, "affordance_logits": aff_logits,
                "aligned": aligned, "trajectory": traj}

    def family_candidates(self, xyz_n, scale, n: int) -> dict[str, torch.Tensor]:
        """One cloud ``xyz_n (1, N, 3)``, ``scale (1,)``: the aligned template and the deformed
        trajectory ``(n, T, 3)`` of each of the ``n`` most probable families (``families
        (n,)``, most probable first), at the predicted contact; the encoder runs once."""
        if len(xyz_n) != 1:
            raise ValueError(f"xyz_n: one cloud at a time, got a batch of {len(xyz_n)}")
        g, feats = backbone_features(self, xyz_n)
        logits = self.cls_head(g)
        aff_logits = self.aff_head(feats)[:, 0]
        aff = torch.sigmoid(aff_logits)
        families = torch.argsort(logits[0], descending=True, stable=True)[:n]
        contact_n = xyz_n[0, aff[0].argmax()][None].expand(n, 3)
        rep = (n, -1, -1)
        aligned, traj = self._deform(xyz_n.expand(*rep), scale.expand(n), feats.expand(*rep),
                                     aff.expand(n, -1), families, contact_n)
        return {"logits": logits, "affordance": aff, "families": families,
                "aligned": aligned, "trajectory": traj}

    def _deform(self, xyz_n, scale, feats, aff, family, contact_n):
        """(aligned template, deformed trajectory) ``(B, T, 3)`` of ``family (B,)`` at
        ``contact_n (B, 3)``."""
        lift = contact_n.new_tensor([0.0, 0.0, self.cfg.release_lift_m])
        aligned = contact_n[:, None] + (self.templates[family] + lift) / scale[:, None, None]
        if self.cfg.condition == "shape":
            shape = masked_max_pool(feats, aff, self.cfg.aff_threshold)
        else:
            shape = feature_at(feats, xyz_n, contact_n)
        x = torch.cat([self.wp_mlp(aligned), shape[:, None].expand(-1, aligned.shape[1], -1)], -1)
        offset = self.offset(self.lstm(x)[0])
        if self.cfg.hang_taper:
            offset = offset * self.taper
        return aligned, aligned + offset


def add_backbone(module: nn.Module, centres, nsample: int, feat_dim: int) -> None:
    """The shared PointNet++ segmentation backbone as attributes ``sa1 … fp1`` of ``module``
    (three set abstractions, a global one, three feature propagations)."""
    c1, c2, c3 = centres
    module.sa1 = SetAbstraction(c1, 0.1, nsample, [3, 32, 32, 64])
    module.sa2 = SetAbstraction(c2, 0.2, nsample, [64 + 3, 64, 64, 128])
    module.sa3 = SetAbstraction(c3, 0.4, nsample, [128 + 3, 128, 128, 256])
    module.sa_global = SetAbstraction(None, 0.0, 0, [256 + 3, 256, 256])
    module.fp3 = FeaturePropagation([256 + 128, 256, 128])
    module.fp2 = FeaturePropagation([128 + 64, 128, 128])
    module.fp1 = FeaturePropagation([128, feat_dim, feat_dim])


def backbone_features(module: nn.Module, xyz_n: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """(global feature ``(B, 256)``, per-point features ``(B, feat_dim, N)``) of the backbone
    that :func:`add_backbone` put on ``module``."""
    l1_xyz, l1 = module.sa1(xyz_n, None)
    l2_xyz, l2 = module.sa2(l1_xyz, l1)
    l3_xyz, l3 = module.sa3(l2_xyz, l2)
    _, g = module.sa_global(l3_xyz, l3)
    f2 = module.fp3(l2_xyz, l3_xyz, l2, l3)
    f1 = module.fp2(l1_xyz, l2_xyz, l1, f2)
    return g[..., 0], module.fp1(xyz_n, l1_xyz, None, f1)


def feature_at(feats: torch.Tensor, xyz_n: torch.Tensor, point_n: torch.Tensor) -> torch.Tensor:
    """The per-point feature ``(B, C)`` of the cloud point nearest ``point_n (B, 3)``."""
    idx = torch.linalg.norm(xyz_n - point_n[:, None], dim=-1).argmin(-1)
    return feats[torch.arange(len(feats)), :, idx]


def masked_max_pool(feats: torch.Tensor, aff: torch.Tensor, threshold: float) -> torch.Tensor:
    """Per-cloud max of ``feats (B, C, N)`` over the points whose affordance ``aff (B, N)``
    exceeds ``threshold`` (over all points of a cloud where none does) → ``(B, C)``.
    Masked-out points are pushed down by 1e4 (features are post-ReLU, far below that)."""
    mask = (aff > threshold).float()
    mask = torch.where(mask.sum(-1, keepdim=True) > 0, mask, torch.ones_like(mask))
    return (feats + (mask[:, None] - 1) * 1e4).max(-1).values


def traj_distance(pred: torch.Tensor, gt: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
    """Mean waypoint distance to the nearest ground-truth SKT: ``pred (B, T, 3)``,
    ``gt (B, G, T, 3)``, ``valid (B, G)`` bool → ``(B,)``."""
    d = torch.linalg.norm(pred[:, None] - gt, dim=-1).mean(-1)  # (B, G)
    return d.masked_fill(~valid, float("inf")).min(-1).values


def sctdn_loss(out, gt, valid, aff_label, family, contact_target, w_aff: float = 0.1,
               w_cls: float = 0.1, w_contact: float = 0.1):
    """L = L_T + 0.1·L_a + 0.1·L_c + 0.1·L_p; cross-entropy on logits (not on softmax outputs).

    L_p (not in the paper) is the cross-entropy between the softmax over the cloud's points of
    the affordance logits and ``contact_target (B, N)``, the view's contact map M_cp as a
    distribution (peaked at the point nearest the true contact): the template is aligned at
    the affordance's argmax, and the per-point MSE of L_a alone left that argmax more than
    1 cm from the contact in most validation views."""
    l_t = traj_distance(out["trajectory"], gt, valid).mean()
    l_a = F.mse_loss(out["affordance"], aff_label)
    l_c = F.cross_entropy(out["logits"], family)
    l_p = -(contact_target * F.log_softmax(out["affordance_logits"], -1)).sum(-1).mean()
    loss = l_t + w_aff * l_a + w_cls * l_c + w_contact * l_p
    return loss, {"traj": l_t.item(), "aff": l_a.item(), "cls": l_c.item(), "contact": l_p.item()}
