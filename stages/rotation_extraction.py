"""rotation_extraction — SE(3) semantic keypoint of every object (paper Fig. 3c).

Inputs:  data/contact_sim/contacts.parquet (objects on the rod), data/mesh_gen/objects.parquet;
         params rotation_extraction.
Outputs: data/rotation_extraction/keypoints.parquet, rotation_extraction.rrd;
         reports/rotation_extraction/{metrics.json, report.md, keypoints.png}.
"""

import logging
import sys
from pathlib import Path

import numpy as np

from skt_lib.config import OBJECT_CATEGORIES, load_sections
from skt_lib.config.rotation_extraction import RotationExtractionParams
from skt_lib.errors import DataError
from skt_lib.geometry.build import OBJECT_RGBA
from skt_lib.geometry.export import read_obj
from skt_lib.geometry.se3 import matrix_to_quat, pose_matrix
from skt_lib.io import read_table, write_table
from skt_lib.schemas import CONTACTS, KEYPOINTS, OBJECTS
from skt_lib.sim.keypoints import keypoint_from_hang, orthonormality_error
from stages._common import parse_args
from viz.figures import Panel, mesh_gallery
from viz.report import Report, write_metrics
from viz.rerun_log import (OBJECT_EYE, OBJECT_LOOK_AT, ItemTimeline, item_blueprint, log_axes, log_mesh,
                           object_path, recording)

log = logging.getLogger("rotation_extraction")


def main(argv=None) -> int:
    args = parse_args("rotation_extraction", argv)
    params = load_sections(args.params, rotation_extraction=RotationExtractionParams)
    p = params.rotation_extraction
    root, out, rep = Path(args.data_root), Path(args.data_dir), Path(args.reports_dir)
    objects = read_table(root / "mesh_gen" / "objects.parquet", OBJECTS).set_index("object_id")
    contacts = read_table(root / "contact_sim" / "contacts.parquet", CONTACTS)
    on_rod = contacts[contacts["kind"] == "object_on_rod"].set_index("object_id")

    rows, missing, errors = [], [], []
    for object_id, obj in objects.iterrows():
        if object_id not in on_rod.index or not on_rod.loc[object_id, "ok"]:
            missing.append(object_id)
            continue
        c = on_rod.loc[object_id]
        kp = keypoint_from_hang(pose_matrix(c["hang_position"], c["hang_quat"]),
                                c["contact_object"], p.front_offset_m)
        errors.append(orthonormality_error(kp.rotation))
        rows.append({"object_id": object_id, "category": obj["category"],
                     "is_reference": bool(obj["is_reference"]),
                     "position": kp.position.tolist(), "quat": matrix_to_quat(kp.rotation).tolist(),
                     "rotation": kp.rotation.reshape(-1).tolist(),
                     "p_hang": kp.p_hang.tolist(), "p_front": kp.p_front.tolist()})
    if not rows:
        raise DataError(f"{root / 'contact_sim' / 'contacts.parquet'}: no object hung on the rod")
    write_table(out / "keypoints.parquet", rows, KEYPOINTS)
    write_metrics(rep, {"n_keypoints": len(rows), "n_missing": len(missing),
                        "missing": sorted(missing),
                        "max_orthonormality_error": max(errors)})

    meshes = {o: read_obj(root / "mesh_gen" / objects.loc[o, "mesh_path"])[0] for o in objects.index}
    bp = item_blueprint("keypoint frame (x red: motion into the hang)", "object", OBJECT_EYE,
                        OBJECT_LOOK_AT)
    with recording("rotation_extraction", out / "rotation_extraction.rrd", "rotation_extraction",
                   bp) as rec:
        items = ItemTimeline(rec, "object")
        for r in rows:
            e, m = object_path(r["object_id"]), meshes[r["object_id"]]
            items.next(e, r["object_id"], category=r["category"])
            log_mesh(rec, e, m.vertices, m.faces, OBJECT_RGBA[r["category"]])
            log_axes(rec, f"{e}/keypoint", r["position"], np.reshape(r["rotation"], (3, 3)))

    report = Report("rotation_extraction", rep)
    report.text(f"{len(rows)} keypoints ({len(missing)} objects without a hang: "
                f"{', '.join(missing) or 'none'}). Approach: threading onto the rod along −x; "
                f"P_front = P_hang moved back {p.front_offset_m} m along it. "
                f"Max orthonormality error {max(errors):.2e}.")
    report.heading("Keypoint frames (x red = motion into the hang, y green, z blue)")
    panels = [Panel(r["object_id"], [(meshes[r["object_id"]].vertices, meshes[r["object_id"]].faces,
                                      OBJECT_RGBA[r["category"]])],
                    points=np.array([r["position"]]),
                    frames=[(np.array(r["position"]), np.reshape(r["rotation"], (3, 3)))])
              for c in (*OBJECT_CATEGORIES, "reference") for r in rows if r["category"] == c][:12]
    mesh_gallery(panels, report.figure("keypoints.png", "Objects in their own frame with the "
                                       "keypoint frame"), azim=-40)
    report.table(["object", "category", "position (m, object frame)", "x axis"],
                 [[r["object_id"], r["category"], np.round(r["position"], 4).tolist(),
                   np.round(np.reshape(r["rotation"], (3, 3))[:, 0], 3).tolist()] for r in rows])
    report.recording("object")
    report.write()
    log.info("%d keypoints, %d missing", len(rows), len(missing))
    return 0


if __name__ == "__main__":
    sys.exit(main())
