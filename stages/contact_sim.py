"""contact_sim — forward-simulated hangs: object keypoints and support contact points.

Inputs:  data/mesh_gen/{supports,objects}.parquet and their URDFs; params common,
         compute, contact_sim.
Outputs: data/contact_sim/contacts.parquet (one row per object on the rod and per support
         with the reference object), contact_sim.rrd; reports/contact_sim/{metrics.json,
         report.md, PNGs}.
"""

import logging
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np

from skt_lib.config import LEVELS, OBJECT_CATEGORIES, load_params
from skt_lib.geometry.build import OBJECT_RGBA, SUPPORT_RGBA
from skt_lib.geometry.export import read_obj
from skt_lib.geometry.se3 import pose_matrix, transform_points
from skt_lib.io import read_table, write_table
from skt_lib.schemas import CONTACTS, OBJECTS, SUPPORTS
from skt_lib.sim.contact_sim import ROD_ARM, ROD_SITE, HangTask, simulate_hangs
from stages._common import item_store, parse_args, run_items
from viz.figures import Panel, mesh_gallery
from viz.report import Report, write_metrics, write_run_log
from viz.rerun_log import (SUPPORT_EYE, SUPPORT_LOOK_AT, ItemTimeline, item_blueprint, log_mesh,
                           log_points, object_path, recording, support_path)

log = logging.getLogger("contact_sim")


def main(argv=None) -> int:
    args = parse_args("contact_sim", argv)
    params = load_params(args.params)
    p, seed = params.contact_sim, params.common.seed
    src, out, rep = Path(args.data_root) / "mesh_gen", Path(args.data_dir), Path(args.reports_dir)
    supports = read_table(src / "supports.parquet", SUPPORTS)
    objects = read_table(src / "objects.parquet", OBJECTS)
    ref = objects[objects["is_reference"]].iloc[0]

    obj_tasks = [HangTask(o.object_id, "object_on_rod", o.object_id, str(src / o.urdf_path),
                          o.aperture_clearance_m, "", "", ROD_ARM, ROD_SITE, p.rod_radius_m, seed, p)
                 for o in objects.itertuples()]
    sup_tasks = [HangTask(s.support_id, "reference_on_support", ref.object_id, str(src / ref.urdf_path),
                          ref.aperture_clearance_m, s.support_id, str(src / s.urdf_path),
                          tuple(map(tuple, s.arm_centreline)), tuple(s.hang_point), s.radius_m, seed, p)
                 for s in supports.itertuples()]
    work = item_store(args)
    t0 = time.perf_counter()
    obj_rows, obj_fail, obj_failed = run_items(simulate_hangs, obj_tasks, params.compute,
                                               "objects on rod", work=work)
    t_obj = time.perf_counter() - t0
    sup_rows, sup_fail, sup_failed = run_items(simulate_hangs, sup_tasks, params.compute,
                                               "reference on supports", work=work)
    t_sup = time.perf_counter() - t0 - t_obj
    write_run_log(Path(args.log_dir), "contact_sim", {
        "objects_wall_s": t_obj, "supports_wall_s": t_sup,
        "objects_s_per_item": t_obj / max(1, len(obj_tasks)),
        "supports_s_per_item": t_sup / max(1, len(sup_tasks))})
    raised = obj_failed + sup_failed  # items that raised an expected failure: no row
    for task, f in raised:
        log.error("%s (%s): %s: %s", task.item_id, task.kind, f.reason, f.message)
    rows = obj_rows + sup_rows
    write_table(out / "contacts.parquet", rows, CONTACTS)

    level = dict(zip(supports["support_id"], supports["difficulty"]))
    sup_ok = [r for r in sup_rows if r["ok"]]
    real = [r for r in obj_rows if r["object_id"] != ref.object_id]
    metrics = {  # denominators are the tasks: an item that raised counts as failed
        "n_supports": len(sup_tasks),
        "n_supports_ok": len(sup_ok),
        "support_success_rate": len(sup_ok) / max(1, len(sup_tasks)),
        "n_objects": sum(t.object_id != ref.object_id for t in obj_tasks),
        "n_objects_ok": sum(r["ok"] for r in real),
        "reference_ok": any(r["ok"] for r in obj_rows if r["object_id"] == ref.object_id),
        "supports_ok_by_difficulty": {lv: sum(r["ok"] and level[r["support_id"]] == lv for r in sup_rows)
                                      for lv in LEVELS},
        "drop_success_rate": (sum(r["n_success"] for r in rows)
                              / max(1, sum(r["n_attempts"] for r in rows))),
        "failures_by_reason": dict(sorted((Counter(r["failure_reason"] for r in rows if not r["ok"])
                                           + obj_fail + sup_fail).items())),
        "n_items_raised": len(raised),
        "items_raised": {t.item_id: f.reason for t, f in raised},
    }
    write_metrics(rep, metrics)

    meshes = {r.support_id: read_obj(src / r.mesh_path)[0] for r in supports.itertuples()}
    meshes |= {r.object_id: read_obj(src / r.mesh_path)[0] for r in objects.itertuples()}
    poses = {r["item_id"]: pose_matrix(r["hang_position"], r["hang_quat"]) for r in rows if r["ok"]}
    bp = item_blueprint("contact_sim: the hang and its contact point", "support", SUPPORT_EYE,
                        SUPPORT_LOOK_AT)
    with recording("contact_sim", out / "contact_sim.rrd", "contact_sim", bp) as rec:
        items = ItemTimeline(rec, "support")
        for r in sup_rows:
            e, m = support_path(r["support_id"]), meshes[r["support_id"]]
            items.next(e, r["support_id"], level=level[r["support_id"]],
                       hung="yes" if r["ok"] else f"no ({r['failure_reason']})")
            log_mesh(rec, e, m.vertices, m.faces, SUPPORT_RGBA)
            if r["ok"]:
                log_points(rec, f"{e}/contact", r["contact_support"], labels=["contact"])
                rm = meshes[ref.object_id]
                log_mesh(rec, f"{e}/reference", rm.vertices, rm.faces, OBJECT_RGBA["reference"],
                         pose=poses[r["support_id"]])
        items = ItemTimeline(rec, "object")
        category = objects.set_index("object_id")["category"]
        for r in obj_rows:  # hung on the rod (rod frame)
            e, m = object_path(r["object_id"]), meshes[r["object_id"]]
            items.next(e, r["object_id"], category=category[r["object_id"]],
                       hung="yes" if r["ok"] else f"no ({r['failure_reason']})")
            if r["ok"]:
                log_mesh(rec, e, m.vertices, m.faces, OBJECT_RGBA[category[r["object_id"]]],
                         pose=poses[r["object_id"]])
                log_points(rec, f"{e}/contact", r["contact_support"], labels=["contact"])

    report = Report("contact_sim", rep)
    report.text(f"Seed {seed}. Each item: {p.n_drops} releases, {p.drop_steps} drop steps, "
                f"perturbation ±{p.perturb.accel_m_s2} m/s² × {p.perturb.steps_per_direction} steps "
                f"per direction, {p.perturb.settle_steps} settle steps (dt {p.dt:.5f} s).")
    report.heading("Results")
    report.table(["what", "ok", "total"],
                 [["reference on supports", len(sup_ok), len(sup_tasks)],
                  ["objects on the rod", sum(r["ok"] for r in obj_rows), len(obj_tasks)]])
    report.text("Wall-clock times: the git-ignored run log `logs/contact_sim.json`.")
    report.table(["level", "supports ok"], [[lv, f"{metrics['supports_ok_by_difficulty'][lv]} / "
                                             f"{sum(v == lv for v in level.values())}"] for lv in LEVELS])
    report.heading("Failures")
    failed = [r for r in rows if not r["ok"]]
    lines = [f"- `{r['item_id']}` ({r['kind']}): {r['failure_reason']}, {r['n_success']}/"
             f"{r['n_attempts']} drops hung" for r in failed]
    lines += [f"- `{t.item_id}` ({t.kind}): {f.reason} (raised, no result): {f.message}"
              for t, f in raised]
    report.text("\n".join(lines) or "None.")
    report.heading("Pictures")
    ok_by_level = {lv: [r for r in sup_ok if level[r["support_id"]] == lv][:4] for lv in LEVELS}
    panels = [Panel(f"{r['support_id']} ({lv})",
                    [(meshes[r["support_id"]].vertices, meshes[r["support_id"]].faces, SUPPORT_RGBA),
                     (transform_points(poses[r["support_id"]], meshes[ref.object_id].vertices),
                      meshes[ref.object_id].faces, OBJECT_RGBA["reference"])],
                    points=np.array([r["contact_support"]]))
              for lv, rs in ok_by_level.items() for r in rs]
    mesh_gallery(panels, report.figure("reference_hangs.png", "Reference object hung on supports "
                                       "(red: support contact point); one row per level"))
    cat = objects.set_index("object_id")["category"]
    panels = [Panel(f"{r['object_id']}",
                    [(transform_points(poses[r["object_id"]], meshes[r["object_id"]].vertices),
                      meshes[r["object_id"]].faces, OBJECT_RGBA[cat[r["object_id"]]])],
                    points=np.array([r["contact_support"]]))
              for c in (*OBJECT_CATEGORIES, "reference")
              for r in [q for q in obj_rows if q["ok"] and cat[q["object_id"]] == c][:1]]
    mesh_gallery(panels, report.figure("objects_on_rod.png", "One object per category hung on the "
                                       "rod (rod along x; red: contact point)"), ncols=3, azim=-30)
    report.recording("support")
    report.write()
    log.info("supports %d/%d ok, objects %d/%d ok", len(sup_ok), len(sup_tasks),
             sum(r["ok"] for r in obj_rows), len(obj_tasks))
    work.finish()
    return 0


if __name__ == "__main__":
    sys.exit(main())
