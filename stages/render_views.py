"""render_views — partial point clouds of every support from a ring of cameras.

Inputs:  data/mesh_gen/supports.parquet + visual meshes; params common, compute, render_views.
Outputs: data/render_views/<support_id>.npz (points (V, N, 3) float32 support frame,
         cameras (V, 4, 4) float32 camera-to-support OpenCV, n_visible (V,) int32),
         render_views.rrd; with sensor_views_severity > 0 also sensor/<support_id>.npz (the
         same arrays, a depth camera's views) for the training and validation supports;
         reports/render_views/{metrics.json, report.md, views.png}.
"""

import functools
import logging
import sys
import time
from pathlib import Path

import numpy as np

from skt_lib.config import LEVELS, CommonParams, ComputeParams, load_sections
from skt_lib.config.render_views import RenderViewsParams
from skt_lib.errors import DataError
from skt_lib.geometry.build import SUPPORT_RGBA
from skt_lib.geometry.export import read_obj
from skt_lib.io import read_npz, read_table, remove_partial_writes
from skt_lib.perception.camera_views import camera_viewer
from skt_lib.perception.views import RENDER_SPEC, SENSOR_DIR, RenderTask, render_support
from skt_lib.schemas import SUPPORTS
from stages._common import parse_args, run_items
from viz.figures import cloud_grid
from viz.report import Report, write_metrics, write_run_log
from viz.rerun_log import (SUPPORT_EYE, SUPPORT_LOOK_AT, ItemTimeline, item_blueprint, log_camera,
                           log_mesh, log_points, recording, support_path)

log = logging.getLogger("render_views")
REVIEW_PER_LEVEL = 2  # supports per difficulty level in the recording
VIEW_RGB = [(60, 120, 220), (220, 90, 40), (40, 170, 90), (200, 60, 170), (200, 180, 40),
            (60, 190, 200)]


def main(argv=None) -> int:
    args = parse_args("render_views", argv)
    params = load_sections(args.params, common=CommonParams, compute=ComputeParams,
                           render_views=RenderViewsParams)
    p, seed = params.render_views, params.common.seed
    src, out, rep = Path(args.data_root) / "mesh_gen", Path(args.data_dir), Path(args.reports_dir)
    supports = read_table(src / "supports.parquet", SUPPORTS)
    tasks = [RenderTask(s.support_id, str(src / s.mesh_path), str(out / f"{s.support_id}.npz"), seed, p)
             for s in supports.itertuples()]
    t0 = time.perf_counter()
    render = (functools.partial(render_support, viewer=camera_viewer) if p.sensor_severity > 0
              else render_support)
    results, failures, failed = run_items(render, tasks, params.compute, "supports")
    remove_partial_writes(out)  # left by a worker killed mid-write (its task reran)
    wall = time.perf_counter() - t0
    for task, f in failed:
        log.error("%s: %s (%s)", task.support_id, f.reason, f.message)
    if not results:
        raise DataError(f"{src}: no support rendered; failures {dict(failures)}")
    sensor = _sensor_views(supports, src, out / SENSOR_DIR, seed, p, params.compute)
    render_ms = 1000 * np.array([t for r in results for t in r["render_s"]])
    write_run_log(Path(args.log_dir), "render_views", {
        "wall_s": wall, "render_ms_per_view_median": float(np.median(render_ms))})
    n_views = p.n_azimuth * p.n_elevation
    metrics = {
        "n_supports": len(tasks),
        "n_rendered": len(results),
        "n_failed": len(failed),
        "failures_by_reason": dict(sorted(failures.items())),
        "failed_supports": [t.support_id for t, _ in failed],
        "views_per_support": n_views,
        "points_per_view": p.n_points,
        "on_surface_rate": float(np.mean([r["on_surface_rate"] for r in results])),
        "noise_std_m": p.noise_std_m,
        "sensor_severity": p.sensor_severity,
        # a depth camera's views are never rendered again; their flag: the frame fell back
        ("n_views_frame_fallback" if p.sensor_severity > 0 else "n_views_rerendered"):
            sum(r["n_rerendered"] for r in results),
        "n_views_padded": sum(r["n_padded"] for r in results),
        **({"sensor_views": sensor} if sensor else {}),
    }
    write_metrics(rep, metrics)

    done = {r["support_id"]: r for r in results}
    level = supports.set_index("support_id")
    sample = [s for lv in LEVELS
              for s in [s for s in level.index[level["difficulty"] == lv] if s in done][:REVIEW_PER_LEVEL]]
    clouds = {sid: read_npz(out / f"{sid}.npz", RENDER_SPEC) for sid in sample}
    bp = item_blueprint("render_views: partial clouds (every 7th view)", "support", SUPPORT_EYE,
                        SUPPORT_LOOK_AT)
    with recording("render_views", out / "render_views.rrd", "render_views", bp) as rec:
        items = ItemTimeline(rec, "support")
        for sid in sample:
            c, e, row = clouds[sid], support_path(sid), level.loc[sid]
            shown = list(range(0, n_views, 7))
            items.next(e, sid, level=row["difficulty"], family=row["family"], views=n_views,
                       shown=f"{len(shown)} (colour per view)", points_per_view=p.n_points,
                       on_surface_rate=done[sid]["on_surface_rate"])
            m = read_obj(src / row["mesh_path"])[0]
            log_mesh(rec, e, m.vertices, m.faces, (*SUPPORT_RGBA[:3], 0.35))
            for j, v in enumerate(shown):
                rgb = VIEW_RGB[j % len(VIEW_RGB)]
                log_points(rec, f"{e}/views/{v}/cloud", c["points"][v], rgb=rgb, radius=0.0008)
                log_camera(rec, f"{e}/views/{v}/camera", c["cameras"][v], p.width, p.height, p.fov_deg)

    report = Report("render_views", rep)
    report.text(f"{len(results)} of {len(tasks)} supports rendered (failed: "
                f"{metrics['failures_by_reason'] or 'none'}) × {n_views} views × {p.n_points} "
                f"points ({p.width}×{p.height}; wall-clock times: the git-ignored run log "
                "`logs/render_views.json`). " + (
                    f"Depth-camera views (sensor severity {p.sensor_severity:g}, the wall in "
                    "view, the frame found from it); views whose frame fell back to the true "
                    f"camera pose: {metrics['n_views_frame_fallback']}"
                    if p.sensor_severity > 0 else
                    f"Views re-rendered at 2× resolution: {metrics['n_views_rerendered']}") +
                f"; padded with duplicates: {metrics['n_views_padded']}. "
                f"On-surface rate (≤ 1 mm from the mesh): {metrics['on_surface_rate']:.4f}.")
    if sensor:
        report.text(f"Depth-camera views for training (`{SENSOR_DIR}/`, sensor severity "
                    f"{p.sensor_views_severity:g}, the wall in view, the frame found from it): "
                    f"{sensor['n_rendered']} of {sensor['n_supports']} training and validation "
                    f"supports (failed: {sensor['failures_by_reason'] or 'none'}); views whose "
                    f"frame fell back to the true camera pose: {sensor['n_views_frame_fallback']}.")
    report.text("Camera layout: azimuth " + f"{p.azimuth_deg} × elevation {p.elevation_deg} degrees, "
                f"{p.distance_m} m from the support's bounding-box centre, looking at it, +z up.")
    first = list({level.loc[sid, "difficulty"]: sid for sid in reversed(sample)}.values())[::-1]
    cloud_grid([(f"{sid} view {v}", clouds[sid]["points"][v], None) for sid in first for v in (0, 17, 41)
                if v < n_views], report.figure("views.png", "Sample partial clouds (one support per "
                                                "level; views 0, 17, 41)"), ncols=3)
    report.recording("support")
    report.write()
    log.info("%d of %d supports rendered", len(results), len(tasks))
    return 0


def _sensor_views(supports, src: Path, out: Path, seed: int, p: RenderViewsParams,
                  compute) -> dict:
    """With ``sensor_views_severity`` > 0, the training and validation supports' views as a
    depth camera at that severity gives them (each view's generator is the clean view's),
    into ``out``; their figures. Test supports get none: Table I's views stay the others."""
    if p.sensor_views_severity == 0:
        return {}
    q = p.model_copy(update={"sensor_severity": p.sensor_views_severity})
    tasks = [RenderTask(s.support_id, str(src / s.mesh_path), str(out / f"{s.support_id}.npz"),
                        seed, q)
             for s in supports.itertuples() if s.split in ("train", "val")]
    out.mkdir(parents=True, exist_ok=True)
    results, failures, failed = run_items(functools.partial(render_support, viewer=camera_viewer),
                                          tasks, compute, "supports (depth camera)")
    remove_partial_writes(out)
    for task, f in failed:
        log.error("%s (depth camera): %s (%s)", task.support_id, f.reason, f.message)
    return {"severity": p.sensor_views_severity, "n_supports": len(tasks),
            "n_rendered": len(results), "n_failed": len(failed),
            "failures_by_reason": dict(sorted(failures.items())),
            "n_views_frame_fallback": sum(r["n_rerendered"] for r in results)}


if __name__ == "__main__":
    sys.exit(main())
