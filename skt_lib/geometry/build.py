"""Per-item builders run by the executor: draw a shape, check it, write its files.

Each returns one table row (a dict matching :mod:`skt_lib.schemas`) or raises
:class:`~skt_lib.errors.MeshError` when the written files fail their checks. Paths in rows
are relative to ``out_dir`` (the directory of the tables).
"""

from dataclasses import dataclass
from pathlib import Path

from skt_lib.config import LEVELS
from skt_lib.config.mesh_gen import MeshGenParams
from skt_lib.geometry.checks import check_parts, check_solid
from skt_lib.geometry.convex import Mesh, union
from skt_lib.geometry.export import mass_properties, read_obj, write_shape
from skt_lib.geometry.objects import ObjectShape, aperture_clearance, reference_object, sample_object
from skt_lib.geometry.supports import sample_support
from skt_lib.seeding import item_rng

SUPPORT_RGBA = (0.35, 0.22, 0.12, 1.0)
OBJECT_RGBA = {
    "mug": (0.85, 0.85, 0.80, 1.0),
    "cooking_utensil": (0.80, 0.45, 0.15, 1.0),
    "scissor": (0.60, 0.62, 0.68, 1.0),
    "tool": (0.75, 0.10, 0.10, 1.0),
    "other": (0.20, 0.45, 0.80, 1.0),
    "reference": (0.10, 0.70, 0.30, 1.0),
}


@dataclass(frozen=True)
class SupportTask:
    seed: int
    index: int
    params: MeshGenParams
    out_dir: str

    @property
    def support_id(self) -> str:
        return f"support_{self.index:05d}"

    @property
    def target_level(self) -> str:
        return LEVELS[self.index % len(LEVELS)]


@dataclass(frozen=True)
class ObjectTask:
    seed: int
    category: str  # one of CATEGORIES, or "reference"
    index: int
    params: MeshGenParams
    out_dir: str

    @property
    def object_id(self) -> str:
        return "object_reference" if self.category == "reference" else f"object_{self.category}_{self.index:03d}"


def _write_checked(out_dir: Path, sub: str, name: str, visual: Mesh, parts: list[Mesh],
                   density: float, rgba) -> tuple[dict, float, float]:
    """Write files, re-read them and check what was written; returns (paths, iou, mass)."""
    check_solid(visual, name)
    mass, com, inertia = mass_properties(visual, density) if density > 0 else (0.0, [0, 0, 0], [[0] * 3] * 3)
    paths = write_shape(out_dir / sub / name, name, visual, parts, mass, com, inertia, rgba)
    (visual_back,) = read_obj(paths["mesh"])
    parts_back = read_obj(paths["collision"])
    check_solid(visual_back, f"{name} (written)")
    iou = check_parts(parts_back, visual_back, f"{name} (written)")
    rel = {k: str(v.relative_to(out_dir)) for k, v in paths.items()}
    return rel, iou, mass


def build_support(task: SupportTask) -> dict:
    rng = item_rng(task.seed, "mesh_gen/support", task.support_id)
    shape, diff = sample_support(rng, task.target_level, task.params)
    parts = shape.parts()
    visual = union(parts)
    paths, iou, _ = _write_checked(Path(task.out_dir), "supports", task.support_id, visual,
                                   parts, 0.0, SUPPORT_RGBA)
    arm = shape.strokes[0]
    return {
        "support_id": task.support_id,
        "family": shape.family,
        "difficulty": diff.level,
        "split": "",  # assigned once all items exist
        "section": "square" if arm.square else "round",
        "radius_m": arm.radius,
        "blocking_height_m": diff.blocking_height_m,
        "clearance_above_m": diff.clearance_above_m,
        "tip_turn_deg": diff.tip_turn_deg,
        "hang_point": list(diff.hang_point),
        "hang_tangent": list(diff.hang_tangent),
        "arm_centreline": arm.points.tolist(),
        "n_parts": len(parts),
        "volume_m3": visual.volume,
        "part_iou": iou,
        "mesh_path": paths["mesh"],
        "collision_path": paths["collision"],
        "urdf_path": paths["urdf"],
    }


def build_object(task: ObjectTask) -> dict:
    if task.category == "reference":
        shape: ObjectShape = reference_object()
    else:
        rng = item_rng(task.seed, "mesh_gen/object", task.object_id)
        shape = sample_object(rng, task.category, task.params)
    parts = list(shape.parts)
    visual = union(parts)
    paths, iou, mass = _write_checked(Path(task.out_dir), "objects", task.object_id, visual,
                                      parts, task.params.density_kg_m3,
                                      OBJECT_RGBA[shape.category])
    return {
        "object_id": task.object_id,
        "category": shape.category,
        "split": "",  # assigned once all objects exist
        "aperture": shape.aperture,
        "is_reference": task.category == "reference",
        "aperture_clearance_m": aperture_clearance(parts),
        "rod_radius_m": task.params.object_rod_radius_m,
        "n_parts": len(parts),
        "volume_m3": visual.volume,
        "mass_kg": mass,
        "part_iou": iou,
        "mesh_path": paths["mesh"],
        "collision_path": paths["collision"],
        "urdf_path": paths["urdf"],
    }
