"""contact_sim — forward-simulated hangs: object keypoints and support contact points.

Inputs:  data/mesh_gen/{supports,objects}.parquet and their URDFs; params common,
         compute, contact_sim, and sim_eval's object damping (a support's goal hang is judged
         by the evaluation's physics).
Outputs: data/contact_sim/contacts.parquet (one row per object on the rod and per support
         with the reference object), contact_sim.rrd; reports/contact_sim/{metrics.json,
         report.md, PNGs}.
"""

import logging
import sys
import time
from collections import Counter
from pathlib import Path

from skt_lib.config import LEVELS, CommonParams, ComputeParams, load_sections
from skt_lib.config.contact_sim import ContactSimParams
from skt_lib.config.physics import DampingOnly
from skt_lib.geometry.export import read_obj
from skt_lib.geometry.se3 import pose_matrix
from skt_lib.io import read_table, write_table
from skt_lib.schemas import CONTACTS, OBJECTS, SUPPORTS
from skt_lib.sim.contact_sim import (ROD_ARM, ROD_SITE, HangTask, eval_damping, reference_task,
                                     simulate_hangs)
from stages._common import item_store, parse_args, run_items
from viz.contact_sim_report import log_hangs, write_report
from viz.report import write_metrics, write_run_log

log = logging.getLogger("contact_sim")


def main(argv=None) -> int:
    args = parse_args("contact_sim", argv)
    params = load_sections(args.params, common=CommonParams, compute=ComputeParams,
                           contact_sim=ContactSimParams, sim_eval=DampingOnly)
    p, seed = params.contact_sim, params.common.seed
    src, out, rep = Path(args.data_root) / "mesh_gen", Path(args.data_dir), Path(args.reports_dir)
    supports = read_table(src / "supports.parquet", SUPPORTS)
    objects = read_table(src / "objects.parquet", OBJECTS)
    ref = objects[objects["is_reference"]].iloc[0]

    obj_tasks = [HangTask(o.object_id, "object_on_rod", o.object_id, str(src / o.urdf_path),
                          o.aperture_clearance_m, "", "", ROD_ARM, ROD_SITE, p.rod_radius_m, seed, p)
                 for o in objects.itertuples()]
    sup_tasks = [reference_task(s, ref, src, seed, p, eval_damping(params)) for s in supports.itertuples()]
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
        # every goal passed the evaluation's perturbation (undamped tilts); where the most
        # consistent hang did not, a later one became the goal
        "goal_judged_by": "sim_eval perturbation (object damping {} / {}, settle {} / {})".format(
            *eval_damping(params)),
        "goal_medoid_passes_eval_rate": (  # of supports with a hang: the medoid passed at once
            sum(r["goal_rank"] == 0 for r in sup_rows)
            / max(1, sum(r["n_success"] > 0 for r in sup_rows))),
        "n_supports_goal_not_medoid": sum(r["ok"] and r["goal_rank"] > 0 for r in sup_rows),
        "n_supports_goal_moved_along_arm": sum(r["ok"] and r["goal_shift_m"] > 0 for r in sup_rows),
        "n_supports_no_eval_stable_hang_by_level": {
            lv: sum(level[r["support_id"]] == lv and r["failure_reason"].startswith("goal_")
                    for r in sup_rows) for lv in LEVELS},
        "n_items_raised": len(raised),
        "items_raised": {t.item_id: f.reason for t, f in raised},
    }
    write_metrics(rep, metrics)

    meshes = {r.support_id: read_obj(src / r.mesh_path)[0] for r in supports.itertuples()}
    meshes |= {r.object_id: read_obj(src / r.mesh_path)[0] for r in objects.itertuples()}
    poses = {r["item_id"]: pose_matrix(r["hang_position"], r["hang_quat"]) for r in rows if r["ok"]}
    log_hangs(out / "contact_sim.rrd", sup_rows, obj_rows, objects, ref, level, meshes, poses)
    write_report(rep, seed, p, metrics, rows, sup_rows, obj_rows, (len(obj_tasks), len(sup_tasks)),
                 raised, objects, ref, level, meshes, poses)
    log.info("supports %d/%d ok, objects %d/%d ok", len(sup_ok), len(sup_tasks),
             sum(r["ok"] for r in obj_rows), len(obj_tasks))
    work.finish()
    return 0


if __name__ == "__main__":
    sys.exit(main())
