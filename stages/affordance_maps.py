"""affordance_maps — contact, segmentation and affordance maps on every view's cloud.

Inputs:  data/render_views/<support_id>.npz, data/contact_sim/contacts.parquet (support
         contact points), data/rrt_skts/skts.parquet (hanging parts); params affordance_maps.
Outputs: data/affordance_maps/<support_id>.npz (affordance, contact_map, seg_map (V, N)
         float32; contact_index (V,) int32; contact_visible (V,) bool), affordance_maps.rrd;
         reports/affordance_maps/{metrics.json, report.md, examples.png}.
"""

import logging
import sys
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from skt_lib.config import LEVELS, load_sections
from skt_lib.config.affordance_maps import AffordanceMapsParams
from skt_lib.io import read_npz, read_table, write_npz_atomic
from skt_lib.labels.affordance import affordance, hanging_part
from skt_lib.perception.views import RENDER_SPEC
from skt_lib.schemas import CONTACTS, SKTS, SUPPORTS
from stages._common import parse_args
from viz.figures import cloud_grid
from viz.report import Report, write_metrics
from viz.rerun_log import (AFFORDANCE_CMAP, SUPPORT_EYE, SUPPORT_LOOK_AT, ItemTimeline,
                           affordance_colors, item_blueprint, log_colored_points, log_points,
                           recording, support_path)

log = logging.getLogger("affordance_maps")
HIST_BINS = 20  # affordance histogram bins over [0, 1] in the recording


def main(argv=None) -> int:
    args = parse_args("affordance_maps", argv)
    p = load_sections(args.params, affordance_maps=AffordanceMapsParams).affordance_maps
    root, out, rep = Path(args.data_root), Path(args.data_dir), Path(args.reports_dir)
    supports = read_table(root / "mesh_gen" / "supports.parquet", SUPPORTS).set_index("support_id")
    contacts = read_table(root / "contact_sim" / "contacts.parquet", CONTACTS)
    contacts = contacts[(contacts["kind"] == "reference_on_support") & contacts["ok"]].set_index("support_id")
    skts = read_table(root / "rrt_skts" / "skts.parquet", SKTS)
    parts = {sid: np.vstack([hanging_part(np.stack(k), p.hanging_part_m) for k in g["keypoints"]])
             for sid, g in skts.groupby("support_id")}

    n_views = n_visible = n_argmax_ok = 0
    examples, review, skipped = [], [], []
    for sid in supports.index:
        if sid not in parts or sid not in contacts.index:
            skipped.append(sid)
            continue
        cloud = read_npz(root / "render_views" / f"{sid}.npz", RENDER_SPEC)["points"].astype(np.float64)
        contact = np.asarray(contacts.loc[sid, "contact_support"])
        maps = [affordance(pts, contact, parts[sid], p.sigma_m, p.alpha, p.beta) for pts in cloud]
        a, m_cp, m_seg, idx = (np.stack(x) for x in zip(*maps))
        visible = np.linalg.norm(cloud[np.arange(len(cloud)), idx] - contact, axis=1) <= p.visible_tol_m
        best = cloud[np.arange(len(cloud)), a.argmax(1)]
        near = np.linalg.norm(best - contact, axis=1) <= 0.01
        n_views += len(cloud)
        n_visible += int(visible.sum())
        n_argmax_ok += int((near & visible).sum())
        write_npz_atomic(out / f"{sid}.npz", {"affordance": a, "contact_map": m_cp, "seg_map": m_seg,
                                              "contact_index": idx.astype(np.int32),
                                              "contact_visible": visible})
        if len(examples) < 8 and supports.loc[sid, "difficulty"] == LEVELS[len(examples) % 4]:
            v = int(np.flatnonzero(visible)[0]) if visible.any() else 0
            examples.append((f"{sid} view {v}", cloud[v], a[v] / max(p.alpha + p.beta, 1e-9)))
            review.append({"support_id": sid, "view": v, "contact": contact, "part": parts[sid],
                           "contact_visible": bool(visible[v]),
                           "argmax_to_contact_mm": 1000 * float(np.linalg.norm(best[v] - contact))})
    metrics = {"n_views": n_views, "n_supports": len(supports) - len(skipped),
               "n_supports_skipped": len(skipped),
               "contact_visible_rate": n_visible / max(1, n_views),
               "argmax_within_1cm_rate": n_argmax_ok / max(1, n_visible)}
    write_metrics(rep, metrics)

    bp = item_blueprint(f"affordance on the partial cloud ({AFFORDANCE_CMAP}: 0 → 1)", "support", SUPPORT_EYE,
                        SUPPORT_LOOK_AT, side=(rrb.BarChartView(origin="plots/affordance_histogram",
                                                                name="affordance histogram"),))
    with recording("affordance_maps", out / "affordance_maps.rrd", "affordance_maps", bp) as rec:
        items = ItemTimeline(rec, "support")
        for (_, pts, val), r in zip(examples, review):
            sid, e = r["support_id"], support_path(r["support_id"])
            items.next(e, sid, level=supports.loc[sid, "difficulty"],
                       family=supports.loc[sid, "family"], view=r["view"],
                       contact_visible=r["contact_visible"],
                       argmax_to_contact_mm=r["argmax_to_contact_mm"])
            log_colored_points(rec, f"{e}/cloud", pts, affordance_colors(val), radius=0.001)
            log_points(rec, f"{e}/contact", r["contact"], rgb=(40, 200, 255), radius=0.003,
                       labels=["contact"])
            log_points(rec, f"{e}/hanging_part", r["part"], rgb=(90, 220, 90), radius=0.0015)
            counts, edges = np.histogram(val, bins=HIST_BINS, range=(0.0, 1.0))
            rec.log("plots/affordance_histogram",
                    rr.BarChart(counts.astype(np.float64), abscissa=edges[:-1],
                                widths=np.diff(edges)))
    report = Report("affordance_maps", rep)
    report.text(f"{n_views} views. A = {p.alpha}·M_cp + {p.beta}·M_seg, σ = {p.sigma_m} m; hanging "
                f"part = SKT waypoints within {p.hanging_part_m} m of ξ_0. Contact visible (a cloud point "
                f"within {p.visible_tol_m} m) in {metrics['contact_visible_rate']:.3f} of views; "
                f"argmax of A within 1 cm of the contact in {metrics['argmax_within_1cm_rate']:.3f} of "
                f"those. Skipped (no SKT or no contact): {', '.join(skipped) or 'none'}.")
    cloud_grid(examples, report.figure("examples.png", "Affordance (bright = high), two supports per level"))
    report.recording("support")
    report.write()
    log.info("%d views, visible %.3f, argmax %.3f", n_views, metrics["contact_visible_rate"],
             metrics["argmax_within_1cm_rate"])
    return 0


if __name__ == "__main__":
    sys.exit(main())
