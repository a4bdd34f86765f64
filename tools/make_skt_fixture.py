"""Write tests/fixtures/very_hard_skt.npz: one stored Very Hard SKT with what replaying it
needs — the support's mesh, the reference ring's mesh and keypoint frame, the hanging
keypoint — from the artifacts of `make repro` (rrt_skts, contact_sim, rotation_extraction).

    .venv/bin/python tools/make_skt_fixture.py [support_id]
"""

import sys
from pathlib import Path

import numpy as np

from skt_lib.geometry.export import read_obj
from skt_lib.geometry.se3 import pose_matrix
from skt_lib.io import read_table
from skt_lib.schemas import CONTACTS, KEYPOINTS, OBJECTS, SKTS, SUPPORTS

ROOT, OUT = Path("data"), Path("tests/fixtures/very_hard_skt.npz")


def main(support_id: str = "support_00063") -> int:
    supports = read_table(ROOT / "mesh_gen" / "supports.parquet", SUPPORTS).set_index("support_id")
    if supports.loc[support_id, "difficulty"] != "very_hard":
        raise SystemExit(f"ERROR: {support_id} is {supports.loc[support_id, 'difficulty']}, not very_hard")
    skts = read_table(ROOT / "rrt_skts" / "skts.parquet", SKTS)
    skt = skts[skts["support_id"] == support_id].sort_values("skt_index").iloc[0]
    ref = read_table(ROOT / "mesh_gen" / "objects.parquet", OBJECTS).query("is_reference").iloc[0]
    kp = read_table(ROOT / "rotation_extraction" / "keypoints.parquet", KEYPOINTS).set_index("object_id")
    k = pose_matrix(kp.loc[ref.object_id, "position"], kp.loc[ref.object_id, "quat"])
    c = read_table(ROOT / "contact_sim" / "contacts.parquet", CONTACTS).set_index("item_id").loc[support_id]
    hang = (pose_matrix(c["hang_position"], c["hang_quat"]) @ k)[:3, 3]
    (sup,) = read_obj(ROOT / "mesh_gen" / supports.loc[support_id, "mesh_path"])
    (ring,) = read_obj(ROOT / "mesh_gen" / ref.mesh_path)
    np.savez_compressed(OUT, support_id=support_id, keypoints=np.stack(skt["keypoints"]),
                        hang_keypoint=hang, ring_keypoint=k, support_vertices=sup.vertices,
                        support_faces=sup.faces, ring_vertices=ring.vertices, ring_faces=ring.faces)
    print(f"{OUT}: {support_id}, {len(skt['keypoints'])} keypoints")
    return 0


if __name__ == "__main__":
    sys.exit(main(*sys.argv[1:]))
