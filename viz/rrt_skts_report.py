"""rrt_skts' Rerun recording (per support: mesh, SKTs with their waypoint frames, the
reference object hung and at the start) and report (reach-the-hang per level, the test-object
sweeps, failures, sample SKTs per level)."""

from collections import Counter
from pathlib import Path

import rerun.blueprint as rrb

from skt_lib.config import LEVELS
from skt_lib.geometry.build import OBJECT_RGBA, SUPPORT_RGBA
from skt_lib.geometry.skt import resample, skt_frames
from skt_lib.planning.skts import REACH_TOL_M
from viz.figures import Panel, histogram, mesh_gallery
from viz.report import Report
from viz.rerun_log import (
    SKT_EYE,
    SKT_LOOK_AT,
    ItemTimeline,
    item_blueprint,
    log_frames,
    log_mesh,
    log_strip,
    recording,
    support_path,
)


#: SKTs drawn per support in the recording (the first ones; the report's figures use all):
#: Rerun cannot read back a recording of the paper preset's 470 × 50 SKTs, two entities each
#: (its index overflows the reader's flatbuffer limit, ``TooManyTables``), and 50 overlaid
#: paths on one hook are no clearer than 8
MAX_DRAWN_SKTS = 8


def log_skts(path: Path, results: list[dict], supports, meshes: dict, ref_mesh) -> None:
    """The recording: ``results`` of :func:`~skt_lib.planning.skts.plan_support_skts`,
    ``supports`` the supports table indexed by id, ``meshes`` {support_id: mesh}; at most
    :data:`MAX_DRAWN_SKTS` SKTs drawn per support."""
    level = supports["difficulty"]
    bp = item_blueprint("rrt_skts: ground-truth SKTs (reference object at ξ_0 and at the start)",
                        "support", SKT_EYE, SKT_LOOK_AT,
                        side=(rrb.TimeSeriesView(origin="plots", name="per support"),))
    with recording("rrt_skts", path, "rrt_skts", bp) as rec:
        items = ItemTimeline(rec, "support")
        for r in results:
            sid = r["support_id"]
            e, m = support_path(sid), meshes[sid]
            items.next(e, sid, level=level[sid], family=supports.loc[sid, "family"],
                       skts=f"{len(r['skts'])} of {r['n_attempted']} attempted",
                       min_clearance_mm=(1000 * min(k["min_clearance_m"] for k in r["skts"])
                                         if r["skts"] else "-"),
                       failures=", ".join(f"{k} {v}" for k, v in sorted(r["failures"].items())) or "none",
                       **({"drawn": f"the first {MAX_DRAWN_SKTS}"}
                          if len(r["skts"]) > MAX_DRAWN_SKTS else {}))
            items.scalar("skts_planned", len(r["skts"]))
            log_mesh(rec, e, m.vertices, m.faces, SUPPORT_RGBA)
            for s in r["skts"][:MAX_DRAWN_SKTS]:
                log_strip(rec, f"{e}/skt/{s['index']}", s["keypoints"], radius=0.001)
                log_frames(rec, f"{e}/skt/{s['index']}/waypoints",
                           skt_frames(resample(s["keypoints"], 10)), 0.01)
            if r["skts"]:  # poses ξ_0 first: the hanging pose, then out to the start
                poses = r["skts"][0]["poses"]
                log_mesh(rec, f"{e}/reference/hung", ref_mesh.vertices, ref_mesh.faces,
                         OBJECT_RGBA["reference"], pose=poses[0])
                log_mesh(rec, f"{e}/reference/start", ref_mesh.vertices, ref_mesh.faces,
                         (*OBJECT_RGBA["reference"][:3], 0.3), pose=poses[-1])


def write_report(rep: Path, params, metrics: dict, results: list[dict], supports, meshes: dict,
                 attempted_by_level: Counter, reached: Counter, failures: Counter, sweeps: list,
                 sweep_tol_m: float) -> None:
    """``reports/rrt_skts/report.md`` and its figures from the stage's metrics and results."""
    p, level = params.rrt_skts, supports["difficulty"]
    report = Report("rrt_skts", rep)
    report.text(f"{metrics['n_skts']} SKTs on {metrics['n_supports_with_skts']}/{metrics['n_supports']} supports "
                f"({metrics['n_attempted']} attempted: {p.n_skts_per_support} per support, "
                f"{p.n_skts_per_test_support} per test support) on "
                f"{params.compute.n_workers} worker(s). Every stored SKT ends at the hang: ξ_0 within "
                f"{REACH_TOL_M * 1000:.0f} mm of the reference's hanging keypoint (median "
                f"{1000 * (metrics['xi0_error_median_m'] or 0):.1f} mm, max "
                f"{1000 * (metrics['xi0_error_max_m'] or 0):.1f} mm); an attempt that ends elsewhere "
                "is a failure (`off_hang`), never a planned SKT. Re-check (independent, Open3D signed "
                "distance of the reference as executed — SKT frames of the SKT resampled to T = "
                f"{params.clustering.T}, ≤ {p.recheck_step_m * 1000:.1f} mm steps): "
                f"{metrics['recheck_collision_free_rate']:.3f} of planned SKTs pass it. Planner: "
                "threading tree in keypoint space grown from the hang, each node's frame transported "
                f"from its parent's (rotation-minimizing; no pitch limit; edge {p.step_m * 1000:.0f} mm, "
                f"turn ≤ {p.max_turn_deg:.0f}° per edge, straight {p.lead_in_m * 1000:.0f} mm lead-in "
                f"along the hanging keypoint's x, release ≤ {p.max_release_offset_m * 1000:.0f} mm from the hang "
                f"(lifted and/or back along the arrival) where the reference does not fit there; samples: {p.goal_bias:.0%} start region, "
                f"{p.surface_bias:.0%} within {p.surface_offset_m * 1000:.0f} mm of the support's "
                f"surface, the rest uniform; {p.plane_bias:.0%} of them moved onto the vertical plane "
                "through the hang that holds the arrival direction). "
                + ("One search per support: every SKT of a support is read out of one tree grown "
                   "from the hang, each joined to its own start in the start region (SKT 0 to its "
                   "centre)." if p.planner == "one_tree" else
                   "A fresh search per SKT (the reference planner), every SKT to the start "
                   "region's centre.")
                + " Diversity: per support, the mean over pairs of its SKTs of their mean "
                f"waypoint distance at T = {params.clustering.T}, averaged per level.")
    div = metrics.get("skt_diversity_mm_by_level", {})
    report.table(["level", "attempted", "reach the hang", "rate", "SKT diversity (mm)"],
                 [[lv, attempted_by_level[lv], reached[lv],
                   f"{metrics['reaches_hang_rate_by_level'][lv]:.3f}",
                   "–" if div.get(lv) is None else f"{div[lv]:.1f}"] for lv in LEVELS])
    report.heading("Test objects along each test support's first SKT")
    report.text(f"Each test support's first SKT swept with every *test* object at its own keypoint, "
                f"as executed: {metrics['test_sweep_n_pairs']} pairs, "
                f"clear (penetration ≤ {sweep_tol_m * 1000:.0f} mm) "
                f"{100 * (metrics['test_sweep_clear_rate'] or 0):.1f} %, median clearance "
                f"{metrics['test_sweep_clearance_mm_median'] or 0:.1f} mm (capped at 6 mm). Split where "
                f"the keypoint comes within {p.train_objects_from_m * 1000:.0f} mm of the hang for the "
                f"last time: clear on the way there {100 * (metrics['test_sweep_clear_rate_on_way'] or 0):.1f} %, "
                f"clear from there on {100 * (metrics['test_sweep_clear_rate_near_hang'] or 0):.1f} % "
                "(there the object's own pose at the reference's hanging keypoint decides, which no "
                "path changes: each object would settle its own way). Test objects "
                "take no part in planning" + (
                    f"; training objects did (probe), where the keypoint lies "
                    f"{p.train_objects_from_m * 1000:.0f} mm or more from the hang"
                    if p.probe_train_objects else "; training objects were not in the probe") + (
                    f", and were kept off the wall plane from {p.wall_from_m * 1000:.0f} mm from the "
                    "hang on" if p.wall_train_objects else "") + (
                    f" ({metrics['n_attempts_reference_fill']} attempts on "
                    f"{metrics['n_supports_object_probe_fallback']} supports left without an SKT by "
                    "them, planned again for the reference alone; docs/pipeline.md)."
                    if p.probe_train_objects or p.wall_train_objects else " (docs/pipeline.md).")
                + f" The oracles of sim_eval choose among all {p.n_skts_per_test_support} SKTs planned "
                "for a test support, those whose sweep of the object is clear first (docs/evaluation.md); "
                "this figure is the first SKT's alone.")
    if sweeps:
        histogram([1000 * c for c in sweeps], report.figure("test_sweeps.png", "Test-object sweep "
                  "clearance along oracle SKTs (mm, < 0: penetration)"), "clearance", "mm")
    report.table(["failure", "count"], [[k, v] for k, v in sorted(failures.items())] or [["none", 0]])
    panels = []
    for lv in LEVELS:
        for r in [r for r in results if level[r["support_id"]] == lv and r["skts"]][:3]:
            m = meshes[r["support_id"]]
            panels.append(Panel(f"{r['support_id']} ({lv})", [(m.vertices, m.faces, SUPPORT_RGBA)],
                                lines=[s["keypoints"] for s in r["skts"]]))
    mesh_gallery(panels, report.figure("skts_by_level.png", "Sample SKTs (keypoint paths), one row "
                                       "per level"), ncols=3)
    report.recording("support")
    report.write()
