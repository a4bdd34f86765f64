"""rrt_skts on the tiny dataset: contract, goal accuracy, collision-free dense SKTs."""

import json

import numpy as np
import pytest

from skt_lib.geometry.export import read_obj
from skt_lib.geometry.se3 import pose_matrix
from skt_lib.io import read_table
from skt_lib.planning.collision import MeshClearance
from skt_lib.schemas import CONTACTS, KEYPOINTS, OBJECTS, SKTS, SUPPORTS

pytestmark = pytest.mark.slow


def test_contract_goal_and_recheck(tiny_dataset):
    _, data, reports = tiny_dataset
    m = json.loads((reports / "rrt_skts" / "metrics.json").read_text())
    for key in ("n_supports", "n_skts", "plan_success_rate", "plan_time_s_median",
                "recheck_collision_free_rate"):
        assert key in m
    assert m["recheck_collision_free_rate"] == 1.0
    skts = read_table(data / "rrt_skts" / "skts.parquet", SKTS)
    assert len(skts) == m["n_skts"] > 0
    contacts = read_table(data / "contact_sim" / "contacts.parquet", CONTACTS).set_index("item_id")
    kp = read_table(data / "rotation_extraction" / "keypoints.parquet", KEYPOINTS)
    kp = np.array(kp[kp["is_reference"]].iloc[0]["position"])
    supports = read_table(data / "mesh_gen" / "supports.parquet", SUPPORTS).set_index("support_id")
    ref = read_table(data / "mesh_gen" / "objects.parquet", OBJECTS).query("is_reference").iloc[0]
    (ref_mesh,) = read_obj(data / "mesh_gen" / ref["mesh_path"])
    for row in skts.itertuples():
        c = contacts.loc[row.support_id]
        goal = pose_matrix(c["hang_position"], c["hang_quat"])
        keypoints = np.stack(row.keypoints)
        # ξ_0 is the hanging pose's keypoint
        assert np.linalg.norm(keypoints[0] - (goal[:3, :3] @ kp + goal[:3, 3])) < 1e-3
        # dense: keypoint steps ≤ 1 mm
        assert np.linalg.norm(np.diff(keypoints, axis=0), axis=1).max() <= 0.001 + 1e-9
        # an independent re-check from the stored poses says collision-free
        poses = np.stack([pose_matrix(p, q) for p, q in zip(row.positions, row.quats)])
        (sup_mesh,) = read_obj(data / "mesh_gen" / supports.loc[row.support_id, "mesh_path"])
        assert MeshClearance(sup_mesh, ref_mesh, 0.002).clearance(poses) > 0
        # starts in front of the hang
        assert keypoints[-1][0] > keypoints[0][0] + 0.05
