"""VAT-Mart style trajectory proposals (paper §VI-A baselines; authors-code-notes §7):
a PointNet++ affordance module picks the contact point, a conditional VAE proposes
trajectories from it.

- ``condition="contact_point"`` (VAT-Mart): the CVAE is conditioned on the per-point feature
  at the contact point;
- ``condition="shape"`` (modified VAT-Mart): on the shape-conditioned feature, the max-pool
  of the per-point features where the affordance exceeds ``aff_threshold`` (SCTDN's).

A trajectory is ``T`` waypoints relative to the contact point, in the cloud's normalised
frame (:func:`skt_lib.learning.data.normalise`). Encoder ``q(z | τ, c)`` (τ flattened) and
decoder ``p(τ | z, c)`` are MLPs; ``z`` has ``latent`` dimensions. The decoder outputs
``n_control`` control points, linearly interpolated to the ``T`` waypoints (:func:`hat_basis`):
VAT-Mart's trajectories are a handful of waypoints, and a decoder of 40 independent
waypoints left millimetre jitter between neighbours whose SKT-rule frames (x = direction of
motion) flipped from waypoint to waypoint — measured on the first 117 of its trials: median
4461 executed commands against SCTDN's 177, 1 of 117 hung, most refused at set-up (no grasp
could follow the spinning path). Training loss (per cloud):
the mean waypoint distance between the reconstruction and one of the support's ground-truth
SKTs (drawn at random each step: the SKTs of a support are the modes the latent must carry)
+ ``kl_weight`` × KL(q ‖ N(0, I)) summed over the latent + the affordance terms of SCTDN
(0.1 · MSE to the affordance labels, ``contact_weight`` · contact cross-entropy), so the
contact point is learned as well as SCTDN's. At test time each proposal decodes one
``z ~ N(0, I)`` drawn from a caller's seeded generator.

Deviation: the paper's VAT-Mart works on articulated-object interaction; here it shares
SCTDN's backbone, data, budget and contact supervision, so the two differ only in how the
trajectory is produced (a template deformed by an LSTM vs a CVAE sample).
"""

import io
import json
import pickle
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
from torch import nn
from torch.nn import functional as F

from skt_lib.errors import DataError
from skt_lib.learning.data import normalise
from skt_lib.learning.predictor import Skt
from skt_lib.learning.sctdn import (
    CONDITIONS,
    add_backbone,
    backbone_features,
    feature_at,
    masked_max_pool,
)
from skt_lib.perception.pointcloud import check_cloud, farthest_point_sample
from skt_lib.geometry.skt import skt_frames


@dataclass(frozen=True)
class VatMartConfig:
    T: int
    condition: str  # "contact_point" (VAT-Mart) | "shape" (modified VAT-Mart)
    kl_weight: float
    n_points: int = 1000
    latent: int = 128
    hidden: int = 256
    feat_dim: int = 64
    aff_threshold: float = 0.1
    centres: tuple[int, int, int] = (128, 32, 8)
    nsample: int = 16
    n_control: int = 8  # decoded control points, interpolated to the T waypoints

    def __post_init__(self):
        if not 2 <= self.n_control <= self.T:
            raise ValueError(f"n_control: need 2 ≤ n_control ≤ T = {self.T}, got {self.n_control}")
        if self.condition not in CONDITIONS:
            raise ValueError(f"condition: expected one of {CONDITIONS}, got {self.condition!r}")
        object.__setattr__(self, "centres", tuple(int(c) for c in self.centres))
        if not self.n_points >= self.centres[0] >= self.centres[1] >= self.centres[2] >= 3:
            raise ValueError(f"centres: need n_points ≥ c1 ≥ c2 ≥ c3 ≥ 3, got {self.centres}")
        if self.kl_weight < 0 or self.latent < 1 or self.T < 2:
            raise ValueError(f"kl_weight ≥ 0, latent ≥ 1, T ≥ 2 needed, got {self.kl_weight}, "
                             f"{self.latent}, {self.T}")

    def to_json(self) -> str:
        return json.dumps(asdict(self), indent=2, sort_keys=True)

    @classmethod
    def from_json(cls, text: str) -> "VatMartConfig":
        return cls(**json.loads(text))


def _mlp(sizes: list[int]) -> nn.Sequential:
    layers: list[nn.Module] = []
    for a, b in zip(sizes[:-1], sizes[1:]):
        layers += [nn.Linear(a, b), nn.ReLU()]
    return nn.Sequential(*layers[:-1])


class VatMart(nn.Module):
    def __init__(self, cfg: VatMartConfig):
        super().__init__()
        self.cfg = cfg
        add_backbone(self, cfg.centres, cfg.nsample, cfg.feat_dim)
        self.aff_head = nn.Conv1d(cfg.feat_dim, 1, 1)
        self.encoder = _mlp([3 * cfg.T + cfg.feat_dim, cfg.hidden, cfg.hidden, 2 * cfg.latent])
        self.decoder = _mlp([cfg.latent + cfg.feat_dim, cfg.hidden, cfg.hidden, 3 * cfg.n_control])
        self.register_buffer("basis", hat_basis(cfg.T, cfg.n_control), persistent=False)

    def encode_cloud(self, xyz_n, contact_n=None) -> dict[str, torch.Tensor]:
        """Affordance, contact point (given, or the argmax of the affordance) and the
        conditioning feature ``c (B, feat_dim)``."""
        _, feats = backbone_features(self, xyz_n)
        aff_logits = self.aff_head(feats)[:, 0]
        aff = torch.sigmoid(aff_logits)
        if contact_n is None:
            contact_n = xyz_n[torch.arange(len(xyz_n)), aff.argmax(-1)]
        if self.cfg.condition == "shape":
            cond = masked_max_pool(feats, aff, self.cfg.aff_threshold)
        else:
            cond = feature_at(feats, xyz_n, contact_n)
        return {"affordance": aff, "affordance_logits": aff_logits, "contact": contact_n,
                "cond": cond}

    def decode(self, z: torch.Tensor, cond: torch.Tensor, contact_n: torch.Tensor) -> torch.Tensor:
        """Trajectories ``(B, T, 3)`` (normalised frame) for latents ``z (B, latent)``."""
        ctrl = self.decoder(torch.cat([z, cond], -1)).view(len(z), self.cfg.n_control, 3)
        return contact_n[:, None] + self.basis @ ctrl

    def forward(self, xyz_n, target_n, contact_n) -> dict[str, torch.Tensor]:
        """Training pass: ``target_n (B, T, 3)`` the SKT to reconstruct, ``contact_n (B, 3)``
        the true contact (teacher forcing), both in the normalised frame."""
        enc = self.encode_cloud(xyz_n, contact_n)
        rel = (target_n - contact_n[:, None]).flatten(1)
        mu, logvar = self.encoder(torch.cat([rel, enc["cond"]], -1)).chunk(2, -1)
        z = mu + torch.randn_like(mu) * torch.exp(0.5 * logvar)
        return enc | {"trajectory": self.decode(z, enc["cond"], contact_n), "mu": mu,
                      "logvar": logvar}


def hat_basis(T: int, n_control: int) -> torch.Tensor:
    """``(T, n_control)`` weights of piecewise-linear interpolation: waypoint ``i`` (at
    ``i / (T − 1)``) between the control points at ``k / (n_control − 1)``; rows sum to 1,
    the first and last waypoints are the first and last control points."""
    t = torch.linspace(0.0, 1.0, T, dtype=torch.float64)[:, None] * (n_control - 1)
    k = torch.arange(n_control, dtype=torch.float64)[None]
    return (1.0 - (t - k).abs()).clamp_min(0.0).float()


def vatmart_loss(out, target_n, aff_label, contact_target, kl_weight: float,
                 w_aff: float = 0.1, w_contact: float = 0.1):
    """Reconstruction (mean waypoint distance, normalised units) + ``kl_weight`` · KL + the
    affordance terms of :func:`skt_lib.learning.sctdn.sctdn_loss`."""
    l_rec = torch.linalg.norm(out["trajectory"] - target_n, dim=-1).mean()
    l_kl = (-0.5 * (1 + out["logvar"] - out["mu"] ** 2 - out["logvar"].exp()).sum(-1)).mean()
    l_a = F.mse_loss(out["affordance"], aff_label)
    l_p = -(contact_target * F.log_softmax(out["affordance_logits"], -1)).sum(-1).mean()
    loss = l_rec + kl_weight * l_kl + w_aff * l_a + w_contact * l_p
    return loss, {"traj": l_rec.item(), "kl": l_kl.item(), "aff": l_a.item(),
                  "contact": l_p.item()}


def pick_targets(gt: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
    """One valid ground-truth SKT per cloud, uniformly at random (torch's global generator):
    ``gt (B, G, T, 3)``, ``valid (B, G)`` → ``(B, T, 3)``."""
    idx = torch.multinomial(valid.float(), 1)[:, 0]
    return gt[torch.arange(len(gt)), idx]


class VatMartPredictor:
    """A partial cloud in, ``n`` SKT proposals out (the same contact point, different ``z``).

        p = VatMartPredictor.load("data/train_baselines/vatmart")
        skts = p.propose(points, np.random.default_rng(0), n=10)
    """

    def __init__(self, model: VatMart):
        self.model = model.eval()
        self.cfg = model.cfg

    @classmethod
    def load(cls, directory: str | Path) -> "VatMartPredictor":
        d = Path(directory)
        try:
            cfg = VatMartConfig.from_json((d / "vatmart.json").read_text())
            state = torch.load(d / "vatmart.pt", map_location="cpu", weights_only=True)
            model = VatMart(cfg)
            model.load_state_dict(state)
        except (OSError, ValueError, TypeError, KeyError, RuntimeError,
                pickle.UnpicklingError) as err:
            raise DataError(f"{d}: cannot load the VAT-Mart checkpoint: {str(err)[:200]}") from None
        return cls(model)

    def save(self, directory: str | Path) -> None:
        from skt_lib.io import write_bytes_atomic, write_text_atomic

        d = Path(directory)
        d.mkdir(parents=True, exist_ok=True)
        buf = io.BytesIO()  # in memory: see SktPredictor.save
        torch.save(self.model.state_dict(), buf)
        write_bytes_atomic(d / "vatmart.pt", buf.getvalue())
        write_text_atomic(d / "vatmart.json", self.cfg.to_json() + "\n")

    @torch.inference_mode()
    def propose(self, points: np.ndarray, rng: np.random.Generator, n: int) -> list[Skt]:
        """``n`` proposals for a cloud ``(N, 3)`` (support frame, metres); the latents are
        ``rng.standard_normal((n, latent))``, so the same generator state gives the same SKTs."""
        if n < 1:
            raise ValueError(f"n: need at least one proposal, got {n}")
        pts = check_cloud(points, "points")
        if len(pts) < self.cfg.n_points:
            raise ValueError(f"points: need at least {self.cfg.n_points}, got {len(pts)}")
        if len(pts) > self.cfg.n_points:
            pts = pts[farthest_point_sample(pts, self.cfg.n_points)]
        xyz_n, c, s = normalise(pts)
        enc = self.model.encode_cloud(torch.as_tensor(xyz_n[None], dtype=torch.float32))
        z = torch.as_tensor(rng.standard_normal((n, self.cfg.latent)), dtype=torch.float32)
        traj = self.model.decode(z, enc["cond"].expand(n, -1), enc["contact"].expand(n, -1))
        aff = enc["affordance"][0].numpy()
        contact = pts[int(aff.argmax())]
        out = []
        for t in traj.double().numpy() * s + c:
            out.append(Skt(t, skt_frames(t), -1, contact, aff))
        return out
