"""Training and evaluation arrays from the pipeline's artifacts, one entry per support."""

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from skt_lib.errors import DataError
from skt_lib.io import read_npz, read_table
from skt_lib.perception.views import RENDER_SPEC
from skt_lib.geometry.skt import resample
from skt_lib.schemas import CONTACTS, LABELS, SKTS

AFF_SPEC = {"affordance": ("float32", 2), "contact_map": ("float32", 2), "contact_visible": ("bool", 1)}


@dataclass(frozen=True, eq=False)
class SupportData:
    support_id: str
    split: str
    family: int
    points: np.ndarray  # (V, N, 3) float32, support frame
    affordance: np.ndarray  # (V, N) float32
    skts: np.ndarray  # (G, T, 3) float64 ground-truth SKTs resampled to T, ξ_0 first
    contact: np.ndarray  # (3,) support contact point
    contact_map: np.ndarray  # (V, N) float32 M_cp of affordance_maps (Gaussian at the point nearest the contact)
    contact_visible: np.ndarray  # (V,) bool: the contact is within affordance_maps.visible_tol_m of a point
    level: str = ""  # difficulty level (easy … very_hard), for per-level reports


def load_supports(root: Path, T: int) -> list[SupportData]:
    labels = read_table(root / "clustering" / "labels.parquet", LABELS)
    skts = read_table(root / "rrt_skts" / "skts.parquet", SKTS)
    contacts = read_table(root / "contact_sim" / "contacts.parquet", CONTACTS)
    contacts = contacts[contacts["kind"] == "reference_on_support"].set_index("item_id")
    by_support = {sid: g.sort_values("skt_index") for sid, g in skts.groupby("support_id")}
    out = []
    for row in labels.itertuples():
        cloud = read_npz(root / "render_views" / f"{row.support_id}.npz", RENDER_SPEC)
        aff = read_npz(root / "affordance_maps" / f"{row.support_id}.npz", AFF_SPEC)
        gt = np.stack([resample(np.stack(k), T) for k in by_support[row.support_id]["keypoints"]])
        out.append(SupportData(row.support_id, row.split, int(row.category), cloud["points"],
                               aff["affordance"], gt,
                               np.asarray(contacts.loc[row.support_id, "contact_support"]),
                               aff["contact_map"], aff["contact_visible"], row.difficulty))
    return out


@dataclass(frozen=True, eq=False)
class TrainingSet:
    templates: np.ndarray  # (k, T, 3) family templates, metres relative to ξ_0
    train: list[SupportData]
    val: list[SupportData]

    @property
    def T(self) -> int:
        return self.templates.shape[1]

    @property
    def k(self) -> int:
        return self.templates.shape[0]

    @property
    def n_points(self) -> int:
        return self.train[0].points.shape[1]


def load_training_set(root: Path) -> TrainingSet:
    """The templates of ``clustering`` and the training and validation supports; a
    :class:`DataError` when either split is empty (model selection is on validation
    supports, never on training ones)."""
    tz = read_npz(root / "clustering" / "templates.npz", {"templates": ("float64", 3)})
    supports = load_supports(root, int(tz["T"]))
    train = [s for s in supports if s.split == "train"]
    val = [s for s in supports if s.split == "val"]
    if not train or not val:
        raise DataError(f"{root / 'mesh_gen'}: {len(train)} training and {len(val)} validation "
                        "supports with labels; model selection needs both (set "
                        "mesh_gen.n_val_per_level ≥ 1) — it never selects on training supports")
    return TrainingSet(tz["templates"], train, val)


def normalise(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(normalised points, centroid (…, 3), scale (…)) per cloud ``(..., N, 3)``."""
    c = points.mean(-2, keepdims=True)
    s = np.linalg.norm(points - c, axis=-1).max(-1)
    return (points - c) / s[..., None, None], c[..., 0, :], s
