"""affordance_maps — contact, segmentation and affordance maps on every view's cloud.

Inputs:  data/render_views/<support_id>.npz, data/contact_sim/contacts.parquet (support
         contact points), data/rrt_skts/skts.parquet (hanging parts); params affordance_maps.
Outputs: data/affordance_maps/<support_id>.npz (affordance, contact_map, seg_map (V, N)
         float32; contact_index (V,) int32; contact_visible (V,) bool), affordance_maps.rrd;
         reports/affordance_maps/{metrics.json, report.md, examples.png}; the same maps of
         render_views' depth-camera views in sensor/<support_id>.npz where it has them.
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
from skt_lib.perception.views import RENDER_SPEC, SENSOR_DIR
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

    # views, contact visible, argmax within 1 cm: render_views' ring, its depth-camera views
    tally = {sub: np.zeros(3, int) for sub in ("", SENSOR_DIR)}
    examples, review, skipped = [], [], []
    for sid in supports.index:
        if sid not in parts or sid not in contacts.index:
            skipped.append(sid)
            continue
        contact = np.asarray(contacts.loc[sid, "contact_support"])
        for sub in tally:
            if sub == "" or (root / "render_views" / sub / f"{sid}.npz").exists():
                maps = _maps(root / "render_views" / sub, out / sub, sid, contact, parts[sid], p)
                tally[sub] += [len(maps[0]), maps[2].sum(), (maps[3] & maps[2]).sum()]
                if sub == "":
                    cloud, a, visible, _ = maps
        if len(examples) < 8 and supports.loc[sid, "difficulty"] == LEVELS[len(examples) % 4]:
            v = int(np.flatnonzero(visible)[0]) if visible.any() else 0
            examples.append((f"{sid} view {v}", cloud[v], a[v] / max(p.alpha + p.beta, 1e-9)))
            review.append({"support_id": sid, "view": v, "contact": contact, "part": parts[sid],
                           "contact_visible": bool(visible[v]),
                           "argmax_to_contact_mm": 1000 * float(
                               np.linalg.norm(cloud[v, a[v].argmax()] - contact))})
    n_views = int(tally[""][0])
    metrics = {**_rates(tally[""]), "n_supports": len(supports) - len(skipped),
               "n_supports_skipped": len(skipped)}
    if tally[SENSOR_DIR][0]:
        metrics["sensor_views"] = _rates(tally[SENSOR_DIR])
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
    if "sensor_views" in metrics:
        sv = metrics["sensor_views"]
        report.text(f"Depth-camera views (`{SENSOR_DIR}/`, for training): {sv['n_views']} views, "
                    f"contact visible in {sv['contact_visible_rate']:.3f}, argmax of A within "
                    f"1 cm in {sv['argmax_within_1cm_rate']:.3f} of those.")
    cloud_grid(examples, report.figure("examples.png", "Affordance (bright = high), two supports per level"))
    report.recording("support")
    report.write()
    log.info("%d views, visible %.3f, argmax %.3f", n_views, metrics["contact_visible_rate"],
             metrics["argmax_within_1cm_rate"])
    return 0


def _rates(tally: np.ndarray) -> dict:
    """The figures of (views, contact visible, argmax within 1 cm of it) counts."""
    n_views, n_visible, n_ok = (int(x) for x in tally)
    return {"n_views": n_views, "contact_visible_rate": n_visible / max(1, n_views),
            "argmax_within_1cm_rate": n_ok / max(1, n_visible)}


def _maps(views: Path, out: Path, sid: str, contact: np.ndarray, part: np.ndarray,
          p: AffordanceMapsParams) -> tuple[np.ndarray, ...]:
    """One support's maps on every view of ``views/<sid>.npz``, written to ``out/<sid>.npz``;
    (the clouds, the affordance, whether the contact is visible, whether the affordance's
    argmax is within 1 cm of it) per view."""
    cloud = read_npz(views / f"{sid}.npz", RENDER_SPEC)["points"].astype(np.float64)
    maps = [affordance(pts, contact, part, p.sigma_m, p.alpha, p.beta) for pts in cloud]
    a, m_cp, m_seg, idx = (np.stack(x) for x in zip(*maps))
    visible = np.linalg.norm(cloud[np.arange(len(cloud)), idx] - contact, axis=1) <= p.visible_tol_m
    best = cloud[np.arange(len(cloud)), a.argmax(1)]
    near = np.linalg.norm(best - contact, axis=1) <= 0.01
    out.mkdir(parents=True, exist_ok=True)
    write_npz_atomic(out / f"{sid}.npz", {"affordance": a, "contact_map": m_cp, "seg_map": m_seg,
                                          "contact_index": idx.astype(np.int32),
                                          "contact_visible": visible})
    return cloud, a, visible, near


if __name__ == "__main__":
    sys.exit(main())
