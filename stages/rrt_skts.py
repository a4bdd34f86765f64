"""rrt_skts — RRT-Connect (OMPL) SKTs of the reference object into every support.

Inputs:  data/mesh_gen (support and reference meshes/URDFs), data/contact_sim/contacts.parquet
         (hanging poses), data/rotation_extraction/keypoints.parquet (reference keypoint);
         params common, compute, rrt_skts.
Outputs: data/rrt_skts/skts.parquet (dense SKTs, ξ_0 at the hang), rrt_skts.rrd;
         reports/rrt_skts/{metrics.json, report.md, PNGs}.
"""

import logging
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np

from skt_lib.config import LEVELS, load_params
from skt_lib.geometry.build import OBJECT_RGBA, SUPPORT_RGBA
from skt_lib.geometry.export import read_obj
from skt_lib.geometry.se3 import matrix_pose, pose_matrix
from skt_lib.io import read_table, write_table
from skt_lib.planning.skts import load_skt_tasks, plan_support_skts
from skt_lib.planning.trajectory import arc_length, resample, skt_frames
from skt_lib.schemas import OBJECTS, SKTS, SUPPORTS
from stages._common import parse_args, run_items
from viz.figures import Panel, histogram, mesh_gallery
from viz.report import Report, write_metrics
from viz.rerun_log import log_axes, log_mesh, log_strip, recording, support_path

log = logging.getLogger("rrt_skts")


def main(argv=None) -> int:
    args = parse_args("rrt_skts", argv)
    params = load_params(args.params)
    p, seed = params.rrt_skts, params.common.seed
    root, out, rep = Path(args.data_root), Path(args.data_dir), Path(args.reports_dir)
    supports = read_table(root / "mesh_gen" / "supports.parquet", SUPPORTS).set_index("support_id")
    ref = read_table(root / "mesh_gen" / "objects.parquet", OBJECTS).query("is_reference").iloc[0]
    tasks = load_skt_tasks(root, seed, p)
    kp = np.asarray(tasks[0].keypoint) if tasks else np.zeros(3)
    mg = root / "mesh_gen"
    t0 = time.perf_counter()
    results, _, _ = run_items(plan_support_skts, tasks, params.compute, "supports")
    wall = time.perf_counter() - t0

    rows, xi0_err = [], []
    for task, r in zip(tasks, results):
        k_goal = pose_matrix(task.goal_position, task.goal_quat)[:3, :3] @ kp + task.goal_position
        for s in r["skts"]:
            pos_quat = [matrix_pose(t) for t in s["poses"]]
            xi0_err.append(float(np.linalg.norm(s["keypoints"][0] - k_goal)))
            rows.append({"support_id": r["support_id"], "skt_index": s["index"],
                         "n_states": len(s["poses"]), "keypoints": s["keypoints"].tolist(),
                         "positions": [q[0].tolist() for q in pos_quat],
                         "quats": [q[1].tolist() for q in pos_quat],
                         "path_length_m": float(arc_length(s["keypoints"])[-1]),
                         "min_clearance_m": s["min_clearance_m"], "n_checks": s["n_checks"]})
    write_table(out / "skts.parquet", rows, SKTS)

    plan_s = [t for r in results for t in r["plan_s"]]
    n_attempted = sum(r["n_attempted"] for r in results)
    n_planned, n_recheck_ok = sum(r["n_planned"] for r in results), sum(r["n_recheck_ok"] for r in results)
    failures = sum((Counter(r["failures"]) for r in results), Counter())
    level = supports["difficulty"]
    by_level = {lv: sum(len(r["skts"]) for r in results if level[r["support_id"]] == lv) for lv in LEVELS}
    metrics = {
        "n_supports": len(tasks), "n_supports_with_skts": sum(bool(r["skts"]) for r in results),
        "n_skts": len(rows), "n_attempted": n_attempted,
        "plan_success_rate": len(rows) / max(1, n_attempted),
        "plan_time_s_median": float(np.median(plan_s)) if plan_s else None,
        "recheck_collision_free_rate": n_recheck_ok / max(1, n_planned),
        "xi0_error_max_m": max(xi0_err, default=None),
        "skts_by_difficulty": by_level,
        "failures_by_reason": dict(sorted(failures.items())),
    }
    write_metrics(rep, metrics)

    meshes = {sid: read_obj(mg / supports.loc[sid, "mesh_path"])[0] for sid in {t.support_id for t in tasks}}
    ref_mesh = read_obj(mg / ref.mesh_path)[0]
    with recording("rrt_skts", out / "rrt_skts.rrd", "rrt_skts: SKTs per support") as rec:
        for k, r in enumerate(results):
            e, m = support_path(r["support_id"]), meshes[r["support_id"]]
            log_mesh(rec, e, m.vertices, m.faces, SUPPORT_RGBA, (0.0, 0.3 * k, 0.0),
                     difficulty=level[r["support_id"]], n_skts=str(len(r["skts"])))
            for s in r["skts"]:
                log_strip(rec, f"{e}/skt/{s['index']}", s["keypoints"])
                for i, f in enumerate(skt_frames(resample(s["keypoints"], 10))):
                    log_axes(rec, f"{e}/skt/{s['index']}/waypoints/{i}", f[:3, 3], f[:3, :3], 0.01)
            if r["skts"] and k < 8:  # the reference object animated along its first SKT
                poses = r["skts"][0]["poses"][::-1]
                for i in range(0, len(poses), 5):
                    rec.set_time("rrt_skts", sequence=i)
                    log_mesh(rec, f"{e}/reference", ref_mesh.vertices, ref_mesh.faces,
                             OBJECT_RGBA["reference"], pose=poses[i])

    report = Report("rrt_skts", rep)
    report.text(f"{len(rows)} SKTs on {metrics['n_supports_with_skts']}/{len(tasks)} supports "
                f"({n_attempted} attempted, {p.n_skts_per_support} per support) in {wall:.1f} s wall on "
                f"{params.compute.n_workers} worker(s). Median plan {metrics['plan_time_s_median']:.3f} s; "
                f"re-check (independent, Open3D signed distance at ≤ {p.recheck_step_m * 1000:.1f} mm steps) "
                f"median {np.median([t for r in results for t in r['recheck_s']] or [0]):.3f} s per SKT.")
    report.table(["level", "SKTs"], [[lv, by_level[lv]] for lv in LEVELS])
    report.table(["failure", "count"], [[k, v] for k, v in sorted(failures.items())] or [["none", 0]])
    histogram(plan_s, report.figure("plan_time.png", "Planning time per attempt"), "plan time", "s")
    panels = []
    for lv in LEVELS:
        for r in [r for r in results if level[r["support_id"]] == lv and r["skts"]][:3]:
            m = meshes[r["support_id"]]
            panels.append(Panel(f"{r['support_id']} ({lv})", [(m.vertices, m.faces, SUPPORT_RGBA)],
                                lines=[s["keypoints"] for s in r["skts"]]))
    mesh_gallery(panels, report.figure("skts_by_level.png", "Sample SKTs (keypoint paths), one row "
                                       "per level"), ncols=3)
    report.write()
    log.info("%d SKTs, success %.3f, recheck %.3f", len(rows), metrics["plan_success_rate"],
             metrics["recheck_collision_free_rate"])
    return 0


if __name__ == "__main__":
    sys.exit(main())
