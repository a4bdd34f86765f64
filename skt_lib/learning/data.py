"""Training and evaluation arrays from the pipeline's artifacts, one entry per support."""

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from skt_lib.errors import DataError
from skt_lib.io import read_npz, read_table
from skt_lib.perception.views import RENDER_SPEC, SENSOR_DIR
from skt_lib.geometry.skt import resample
from skt_lib.schemas import CONTACTS, LABELS, SKTS

#: What each ``train_baselines.views`` value loads: folders under render_views/ and
#: affordance_maps/, their views concatenated in this order.
VIEW_DIRS = {"clean": ("",), "sensor": (SENSOR_DIR,), "both": ("", SENSOR_DIR)}
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


def load_supports(root: Path, T: int, views: str = "clean",
                  splits: tuple[str, ...] | None = None) -> list[SupportData]:
    """Every labelled support of ``splits`` (all when None) with the views ``views``
    (:data:`VIEW_DIRS`): ``clean`` = ``render_views``' ring, ``sensor`` = its depth-camera
    views (:data:`SENSOR_DIR`), ``both`` = the clean views followed by the sensor ones (view
    ``v`` < 42 is still clean view ``v``)."""
    if views not in VIEW_DIRS:
        raise ValueError(f"views: {views!r} is not one of {sorted(VIEW_DIRS)}")
    labels = read_table(root / "clustering" / "labels.parquet", LABELS)
    skts = read_table(root / "rrt_skts" / "skts.parquet", SKTS)
    contacts = read_table(root / "contact_sim" / "contacts.parquet", CONTACTS)
    contacts = contacts[contacts["kind"] == "reference_on_support"].set_index("item_id")
    by_support = {sid: g.sort_values("skt_index") for sid, g in skts.groupby("support_id")}
    dirs = VIEW_DIRS[views]
    out = []
    for row in labels.itertuples():
        if splits is not None and row.split not in splits:
            continue
        cloud, aff = zip(*(_views(root, sub, row.support_id) for sub in dirs))
        gt = np.stack([resample(np.stack(k), T) for k in by_support[row.support_id]["keypoints"]])
        out.append(SupportData(row.support_id, row.split, int(row.category),
                               np.concatenate([c["points"] for c in cloud]),
                               np.concatenate([a["affordance"] for a in aff]), gt,
                               np.asarray(contacts.loc[row.support_id, "contact_support"]),
                               np.concatenate([a["contact_map"] for a in aff]),
                               np.concatenate([a["contact_visible"] for a in aff]), row.difficulty))
    return out


def _views(root: Path, sub: str, support_id: str) -> tuple[dict, dict]:
    """One support's clouds and their affordance maps from ``render_views/<sub>`` and
    ``affordance_maps/<sub>``; a :class:`DataError` naming the setting when the depth-camera
    views were never rendered."""
    cloud_path = root / "render_views" / sub / f"{support_id}.npz"
    if sub and not cloud_path.exists():
        raise DataError(f"{cloud_path}: no depth-camera views of {support_id} for "
                        "train_baselines.views: render_views makes them when "
                        "render_views.sensor_views_severity > 0 (its report names a support "
                        "that failed there)")
    return (read_npz(cloud_path, RENDER_SPEC),
            read_npz(root / "affordance_maps" / sub / f"{support_id}.npz", AFF_SPEC))


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


def load_training_set(root: Path, views: str = "clean") -> TrainingSet:
    """The templates of ``clustering`` and the training and validation supports with the
    views ``views`` (:func:`load_supports`); a :class:`DataError` when either split is empty
    (model selection is on validation supports, never on training ones)."""
    tz = read_npz(root / "clustering" / "templates.npz", {"templates": ("float64", 3)})
    supports = load_supports(root, int(tz["T"]), views, ("train", "val"))
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
