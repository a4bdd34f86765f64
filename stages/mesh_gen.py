"""mesh_gen — procedural supporting items and hangable objects (replaces Point-E).

Inputs:  params.yaml sections common, compute, mesh_gen.
Outputs: data/mesh_gen/supports.parquet, objects.parquet, supports/<id>/, objects/<id>/
         (visual.obj, collision.obj, <id>.urdf), mesh_gen.rrd;
         reports/mesh_gen/metrics.json, report.md, gallery PNGs.
"""

import logging
import shutil
import sys
import time
from collections import Counter
from pathlib import Path

from skt_lib.config import LEVELS, OBJECT_CATEGORIES, CommonParams, ComputeParams, load_sections
from skt_lib.config.mesh_gen import MeshGenParams
from skt_lib.geometry.build import OBJECT_RGBA, SUPPORT_RGBA, ObjectTask, SupportTask, build_object, build_support
from skt_lib.geometry.export import read_obj
from skt_lib.geometry.splits import assign_splits
from skt_lib.io import remove_partial_writes, write_table
from skt_lib.schemas import OBJECTS, SUPPORTS
from stages._common import parse_args, run_items
from viz.figures import Panel, bar_chart, mesh_gallery
from viz.report import Report, write_metrics, write_run_log
from viz.rerun_log import (SUPPORT_EYE, SUPPORT_LOOK_AT, ItemTimeline, item_blueprint, log_mesh,
                           object_path, recording, support_path)

log = logging.getLogger("mesh_gen")
GALLERY_PER_GROUP = 8


def main(argv=None) -> int:
    args = parse_args("mesh_gen", argv)
    params = load_sections(args.params, common=CommonParams, compute=ComputeParams,
                           mesh_gen=MeshGenParams)
    p, seed = params.mesh_gen, params.common.seed
    out, rep = Path(args.data_dir), Path(args.reports_dir)
    for sub in ("supports", "objects"):
        shutil.rmtree(out / sub, ignore_errors=True)

    t0 = time.perf_counter()
    tasks = [SupportTask(seed, i, p, str(out)) for i in range(p.n_supports + p.n_extra_train_supports)]
    supports, s_fail, s_failed = run_items(build_support, tasks, params.compute, "supports")
    t_sup = time.perf_counter() - t0
    otasks = [ObjectTask(seed, "reference", 0, p, str(out))]
    otasks += [ObjectTask(seed, c, k, p, str(out)) for c in OBJECT_CATEGORIES
               for k in range(p.n_objects_per_category)]
    objects, o_fail, o_failed = run_items(build_object, otasks, params.compute, "objects")
    remove_partial_writes(out)  # left by a worker killed mid-write (its task reran)
    t_obj = time.perf_counter() - t0 - t_sup
    if not any(o["is_reference"] for o in objects):
        log.error("the reference object failed: %s", o_failed)
        return 1

    split_ids = {t.support_id for t in tasks[:p.n_supports]}  # the split is drawn from these
    drawn = [s for s in supports if s["support_id"] in split_ids]
    splits = assign_splits([s["support_id"] for s in drawn], [s["difficulty"] for s in drawn],
                           seed, p.n_val_per_level, p.n_test_per_level)
    for s in supports:
        s["split"] = "train"  # the extra supports: n_extra_train_supports
    for s, split in zip(drawn, splits):
        s["split"] = split
    real = [o for o in objects if not o["is_reference"]]
    o_splits = assign_splits([o["object_id"] for o in real], [o["category"] for o in real], seed, 0,
                             p.n_test_objects_per_category, OBJECT_CATEGORIES, "mesh_gen/object_split")
    for o, split in zip(real, o_splits):
        o["split"] = split
    for o in objects:
        if o["is_reference"]:
            o["split"] = "train"  # the reference object makes the labels
    write_table(out / "supports.parquet", supports, SUPPORTS)
    write_table(out / "objects.parquet", objects, OBJECTS)

    by_level = Counter(s["difficulty"] for s in supports)
    test_level = Counter(s["difficulty"] for s in supports if s["split"] == "test")
    metrics = {
        "n_supports": len(supports),
        "n_objects": len(real),
        "supports_by_difficulty": {lv: by_level[lv] for lv in LEVELS},
        "test_supports_by_difficulty": {lv: test_level[lv] for lv in LEVELS},
        "supports_by_split": dict(sorted(Counter(s["split"] for s in supports).items())),
        "n_extra_train_supports": len(supports) - len(drawn),
        "supports_by_family": dict(sorted(Counter(s["family"] for s in supports).items())),
        "objects_by_category": {c: sum(o["category"] == c for o in real) for c in OBJECT_CATEGORIES},
        "test_objects_by_category": {c: sum(o["category"] == c and o["split"] == "test" for o in real)
                                     for c in OBJECT_CATEGORIES},
        "n_invalid": len(s_failed) + len(o_failed),
        "failures_by_reason": dict(sorted((s_fail + o_fail).items())),
        "min_part_iou": min(r["part_iou"] for r in supports + objects),
        "min_aperture_clearance_m": min(o["aperture_clearance_m"] for o in objects),
    }
    write_metrics(rep, metrics)

    meshes = {r.get("support_id", r.get("object_id")): read_obj(out / r["mesh_path"])[0]
              for r in supports + objects}
    bp = item_blueprint("mesh_gen: one item at a time", "support", SUPPORT_EYE, SUPPORT_LOOK_AT)
    with recording("mesh_gen", out / "mesh_gen.rrd", "mesh_gen", bp) as rec:
        items = ItemTimeline(rec, "support")
        for s in supports:
            m, e = meshes[s["support_id"]], support_path(s["support_id"])
            items.next(e, s["support_id"], level=s["difficulty"], family=s["family"],
                       split=s["split"], blocking_height_cm=100 * s["blocking_height_m"],
                       convex_parts=s["n_parts"], part_iou=s["part_iou"])
            log_mesh(rec, e, m.vertices, m.faces, SUPPORT_RGBA)
        items = ItemTimeline(rec, "object")
        for o in objects:
            m, e = meshes[o["object_id"]], object_path(o["object_id"])
            items.next(e, o["object_id"], category=o["category"], aperture=o["aperture"],
                       split=o["split"], aperture_clearance_mm=1000 * o["aperture_clearance_m"],
                       mass_kg=o["mass_kg"], convex_parts=o["n_parts"])
            log_mesh(rec, e, m.vertices, m.faces, OBJECT_RGBA[o["category"]])

    report = Report("mesh_gen", rep)
    report.text(f"Seed {seed}; {len(supports)} supports and {len(real)} objects (+ the reference "
                f"object) on {params.compute.n_workers} {params.compute.backend} worker(s); wall-clock "
                "times: the git-ignored run log `logs/mesh_gen.json`.")
    write_run_log(Path(args.log_dir), "mesh_gen", {
        "supports_wall_s": t_sup, "supports_s_per_item": t_sup / max(1, len(tasks)),
        "objects_wall_s": t_obj, "objects_s_per_item": t_obj / max(1, len(otasks))})
    report.heading("Counts")
    report.table(["level", "all", "test"], [[lv, by_level[lv], test_level[lv]] for lv in LEVELS])
    report.table(["split", "supports"], [[k, v] for k, v in metrics["supports_by_split"].items()])
    fam = {lv: Counter(s["family"] for s in supports if s["difficulty"] == lv) for lv in LEVELS}
    bar_chart(fam, report.figure("families_by_level.png", "Families per difficulty level"),
              "supports per family and level")
    report.heading("Failures")
    report.text("None." if not (s_failed or o_failed) else "\n".join(
        f"- `{getattr(t, 'support_id', getattr(t, 'object_id', '?'))}`: {f.reason} — {f.message}"
        for t, f in s_failed + o_failed))
    report.heading("Galleries")
    for lv in LEVELS:
        items = [Panel(f"{s['support_id']} {s['family']}\nh={s['blocking_height_m'] * 100:.1f} cm",
                       [(meshes[s["support_id"]].vertices, meshes[s["support_id"]].faces, SUPPORT_RGBA)])
                 for s in supports if s["difficulty"] == lv][:GALLERY_PER_GROUP]
        mesh_gallery(items, report.figure(f"gallery_{lv}.png", f"{lv} supports (h: blocking height)"))
    for c in (*OBJECT_CATEGORIES, "reference"):
        items = [Panel(o["object_id"], [(meshes[o["object_id"]].vertices, meshes[o["object_id"]].faces,
                                         OBJECT_RGBA[c])])
                 for o in objects if o["category"] == c][:GALLERY_PER_GROUP]
        mesh_gallery(items, report.figure(f"objects_{c}.png", f"{c} objects"), elev=10, azim=-20)
    report.recording("support")
    report.write()
    log.info("wrote %d supports, %d objects, %d invalid", len(supports), len(objects),
             metrics["n_invalid"])
    return 0


if __name__ == "__main__":
    sys.exit(main())
