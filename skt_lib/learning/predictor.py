"""The public predictor: a partial cloud of a supporting item in, an SKT out.

    from skt_lib.learning.predictor import SktPredictor
    p = SktPredictor.load("data/train")
    skt = p.predict(points)  # points: (N, 3) float, support frame, metres

Checkpoints are a ``state_dict`` (``sctdn.pt``, loaded with ``weights_only=True``) plus a
JSON config (``sctdn.json``); no pickled objects.
"""

import io
import pickle
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch

from skt_lib.errors import DataError
from skt_lib.learning.cloud_check import clearest
from skt_lib.learning.data import normalise
from skt_lib.learning.sctdn import Sctdn, SctdnConfig
from skt_lib.perception.pointcloud import check_cloud, farthest_point_sample
from skt_lib.geometry.skt import skt_frames


@dataclass(frozen=True, eq=False)
class Skt:
    positions: np.ndarray  # (T, 3) support frame, ξ_0 (hang) first
    frames: np.ndarray  # (T, 4, 4) SE(3) waypoints, SKT frames (skt_lib.geometry.skt)
    family: int
    contact: np.ndarray  # (3,) predicted contact point
    affordance: np.ndarray  # (N,) per input point (after resampling to n_points)
    #: the classifier's softmax probability of ``family`` (NaN where no classifier chose it)
    family_probability: float = float("nan")
    #: the cloud check's other candidates (positions ``(T, 3)``), clearest first: what a
    #: robot's set-up may run instead when it finds no grasp that follows ``positions``
    #: (``sim_eval.setup_fallbacks``); empty where no check ran
    fallbacks: tuple[np.ndarray, ...] = ()


class SktPredictor:
    def __init__(self, model: Sctdn):
        self.model = model.eval()
        self.cfg = model.cfg
        # an aligned template is its family's stored template moved to the contact, so the
        # check scores it with that template's SKT-frame rotations, computed once here
        self._template_rotations = np.stack(
            [skt_frames(t)[:, :3, :3] for t in model.templates.double().numpy()])

    @classmethod
    def load(cls, directory: str | Path) -> "SktPredictor":
        d = Path(directory)
        try:
            cfg = SctdnConfig.from_json((d / "sctdn.json").read_text())
            state = torch.load(d / "sctdn.pt", map_location="cpu", weights_only=True)
            model = Sctdn(cfg, state["templates"])
            model.load_state_dict(state)
        except (OSError, ValueError, TypeError, KeyError, RuntimeError, pickle.UnpicklingError) as err:
            raise DataError(f"{d}: cannot load the SCTDN checkpoint: {str(err)[:200]}") from None
        return cls(model)

    def save(self, directory: str | Path) -> None:
        from skt_lib.io import write_bytes_atomic, write_text_atomic

        d = Path(directory)
        d.mkdir(parents=True, exist_ok=True)
        # Serialised in memory: written to a (randomly named) temp file, torch.save would name
        # the zip's records after it and the bytes would change on every save.
        buf = io.BytesIO()
        torch.save(self.model.state_dict(), buf)
        write_bytes_atomic(d / "sctdn.pt", buf.getvalue())
        write_text_atomic(d / "sctdn.json", self.cfg.to_json() + "\n")

    @torch.inference_mode()
    def predict(self, points: np.ndarray, deform: bool = True) -> Skt:
        """The SKT for a cloud ``(N, 3)``; ``deform=False`` returns the predicted family's
        template aligned at the predicted contact point (the paper's template-only row).

        With ``cfg.check_families = n ≥ 1`` (and ``deform``), the deformed SKT and the aligned
        template of each of the ``n`` most probable families are candidates, in that order,
        and the one whose reference ring cuts least into ``points`` is returned
        (:func:`skt_lib.learning.cloud_check.clearest`); its ``family`` and
        ``family_probability`` are that candidate's, and the others are its ``fallbacks``."""
        pts = check_cloud(points, "points")
        if len(pts) != self.cfg.n_points:
            if len(pts) < self.cfg.n_points:
                raise ValueError(f"points: need at least {self.cfg.n_points}, got {len(pts)}")
            pts = pts[farthest_point_sample(pts, self.cfg.n_points)]
        xyz_n, c, s = normalise(pts)
        x = torch.as_tensor(xyz_n[None], dtype=torch.float32)
        scale = torch.as_tensor([s], dtype=torch.float32)
        fallbacks = ()
        if deform and self.cfg.check_families:
            out = self.model.family_candidates(x, scale, self.cfg.check_families)
            families = out["families"].tolist()
            kinds = np.stack([out["trajectory"].double().numpy(), out["aligned"].double().numpy()],
                             1) * s + c  # (n, 2, T, 3): deformed, then template, per family
            candidates = list(kinds.reshape(-1, *kinds.shape[2:]))
            frames = [f for k, fam in enumerate(families)
                      for f in (skt_frames(kinds[k, 0]), _posed(self._template_rotations[fam],
                                                                kinds[k, 1]))]
            pick, scores = clearest(candidates, pts, rotations=[f[:, :3, :3] for f in frames])
            family, positions = families[pick // 2], candidates[pick]
            # a deformed candidate's frames are its own; a template's equal its stored
            # template's only to rounding (~1e-5 rad), so they are computed for the one returned
            skt_pose = frames[pick] if pick % 2 == 0 else skt_frames(positions)
            fallbacks = tuple(candidates[j] for j in np.argsort(scores, kind="stable") if j != pick)
        else:
            out = self.model(x, scale)
            family = int(out["logits"][0].argmax())
            positions = out["trajectory" if deform else "aligned"][0].double().numpy() * s + c
            skt_pose = skt_frames(positions)
        aff = out["affordance"][0].numpy()
        probs = torch.softmax(out["logits"][0].double(), -1)
        return Skt(positions, skt_pose, family, pts[int(aff.argmax())], aff,
                   float(probs[family]), fallbacks)


def _posed(rotations: np.ndarray, positions: np.ndarray) -> np.ndarray:
    """SE(3) waypoints ``(T, 4, 4)`` from ``rotations (T, 3, 3)`` and ``positions (T, 3)``."""
    out = np.tile(np.eye(4), (len(positions), 1, 1))
    out[:, :3, :3], out[:, :3, 3] = rotations, positions
    return out
