"""Parquet schemas of every table, defined once (documented column by column in docs/, one section per schema)."""

import pyarrow as pa

from skt_lib.io import TableSchema

_VEC3 = pa.list_(pa.float64(), 3)

SUPPORTS = TableSchema(
    "supports",
    1,
    {
        "support_id": pa.string(),
        "family": pa.string(),
        "difficulty": pa.string(),
        "split": pa.string(),
        "section": pa.string(),
        "radius_m": pa.float64(),
        "blocking_height_m": pa.float64(),
        "clearance_above_m": pa.float64(),
        "tip_turn_deg": pa.float64(),
        "hang_point": _VEC3,
        "hang_tangent": _VEC3,
        "arm_centreline": pa.list_(_VEC3),
        "n_parts": pa.int32(),
        "volume_m3": pa.float64(),
        "part_iou": pa.float64(),
        "mesh_path": pa.string(),
        "collision_path": pa.string(),
        "urdf_path": pa.string(),
    },
)

OBJECTS = TableSchema(
    "objects",
    2,
    {
        "object_id": pa.string(),
        "category": pa.string(),
        "split": pa.string(),
        "aperture": pa.string(),
        "is_reference": pa.bool_(),
        "aperture_clearance_m": pa.float64(),
        "rod_radius_m": pa.float64(),
        "n_parts": pa.int32(),
        "volume_m3": pa.float64(),
        "mass_kg": pa.float64(),
        "part_iou": pa.float64(),
        "mesh_path": pa.string(),
        "collision_path": pa.string(),
        "urdf_path": pa.string(),
    },
)

_VEC4 = pa.list_(pa.float64(), 4)

CONTACTS = TableSchema(
    "contacts",
    2,
    {
        "item_id": pa.string(),
        "kind": pa.string(),
        "object_id": pa.string(),
        "support_id": pa.string(),
        "ok": pa.bool_(),
        "failure_reason": pa.string(),
        "n_attempts": pa.int32(),
        "n_success": pa.int32(),
        "n_consistent": pa.int32(),
        "contact_support": _VEC3,
        "contact_object": _VEC3,
        "hang_position": _VEC3,
        "hang_quat": _VEC4,
        "goal_clearance_m": pa.float64(),
        "goal_rank": pa.int32(),  # the successful hang that became the goal (0: the medoid), -1: none
        "goal_shift_m": pa.float64(),  # how far back along the arm its drops were made (NaN: none)
    },
)

KEYPOINTS = TableSchema(
    "keypoints",
    1,
    {
        "object_id": pa.string(),
        "category": pa.string(),
        "is_reference": pa.bool_(),
        "position": _VEC3,
        "quat": _VEC4,
        "rotation": pa.list_(pa.float64(), 9),
        "p_hang": _VEC3,
        "p_front": _VEC3,
    },
)

SKTS = TableSchema(
    "skts",
    1,
    {
        "support_id": pa.string(),
        "skt_index": pa.int32(),
        "n_states": pa.int32(),
        "keypoints": pa.list_(_VEC3),
        "positions": pa.list_(_VEC3),
        "quats": pa.list_(_VEC4),
        "path_length_m": pa.float64(),
        "min_clearance_m": pa.float64(),
        "n_checks": pa.int64(),
    },
)

LABELS = TableSchema(
    "labels",
    1,
    {
        "support_id": pa.string(),
        "split": pa.string(),
        "difficulty": pa.string(),
        "category": pa.int32(),
        "n_skts": pa.int32(),
        "embedding": pa.list_(pa.float64(), 2),
        "is_template": pa.bool_(),
    },
)

TRIALS = TableSchema(
    "trials",
    3,
    {
        "trial_id": pa.string(),
        "method": pa.string(),
        "support_id": pa.string(),
        "object_id": pa.string(),
        "difficulty": pa.string(),
        "category": pa.string(),
        "success": pa.bool_(),
        "failure_reason": pa.string(),
        "n_commands": pa.int32(),
        "n_executed": pa.int32(),
        "max_track_err_m": pa.float64(),
        "touched_support": pa.bool_(),
        "blocked_by": pa.string(),
        "grasp": pa.string(),
        "detail": pa.string(),
        "proposal": pa.int32(),  # 0, or which proposal of a proposing method (VAT-Mart)
    },
)
