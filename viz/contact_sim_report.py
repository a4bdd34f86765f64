"""contact_sim's Rerun recording (per support: mesh, the reference hung, its contact; per
object: hung on the rod) and report (results per level, failures, pictures of hangs)."""

from pathlib import Path

import numpy as np

from skt_lib.config import LEVELS, OBJECT_CATEGORIES
from skt_lib.geometry.build import OBJECT_RGBA, SUPPORT_RGBA
from skt_lib.geometry.se3 import transform_points
from viz.figures import Panel, mesh_gallery
from viz.report import Report
from viz.rerun_log import (
    SUPPORT_EYE,
    SUPPORT_LOOK_AT,
    ItemTimeline,
    item_blueprint,
    log_mesh,
    log_points,
    object_path,
    recording,
    support_path,
)


def log_hangs(path: Path, sup_rows: list[dict], obj_rows: list[dict], objects, ref, level: dict,
              meshes: dict, poses: dict) -> None:
    """The recording: ``sup_rows``/``obj_rows`` rows of ``contacts.parquet``, ``meshes``
    and hanging ``poses`` by item id, ``level`` {support_id: difficulty}."""
    bp = item_blueprint("contact_sim: the hang and its contact point", "support", SUPPORT_EYE,
                        SUPPORT_LOOK_AT)
    with recording("contact_sim", path, "contact_sim", bp) as rec:
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



def write_report(rep: Path, seed: int, p, metrics: dict, rows: list[dict], sup_rows: list[dict],
                 obj_rows: list[dict], n_tasks: tuple[int, int], raised: list, objects, ref,
                 level: dict, meshes: dict, poses: dict) -> None:
    """``reports/contact_sim/report.md`` and its pictures (``p``: the ``contact_sim`` params;
    ``n_tasks``: objects and supports attempted; ``raised``: (task, failure) of items that
    raised)."""
    n_obj_tasks, n_sup_tasks = n_tasks
    sup_ok = [r for r in sup_rows if r["ok"]]
    report = Report("contact_sim", rep)
    report.text(f"Seed {seed}. Each item: {p.n_drops} releases, {p.drop_steps} drop steps, "
                f"perturbation ±{p.perturb.accel_m_s2} m/s² × {p.perturb.steps_per_direction} steps "
                f"per direction, {p.perturb.settle_steps} settle steps (dt {p.dt:.5f} s).")
    report.heading("Results")
    report.table(["what", "ok", "total"],
                 [["reference on supports", len(sup_ok), n_sup_tasks],
                  ["objects on the rod", sum(r["ok"] for r in obj_rows), n_obj_tasks]])
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
