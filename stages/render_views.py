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

from skt_lib.config import CommonParams, ComputeParams, load_sections
from skt_lib.config.render_views import RenderViewsParams
from skt_lib.errors import DataError
from skt_lib.io import read_table, remove_partial_writes
from skt_lib.perception.camera_views import camera_viewer
from skt_lib.perception.views import SENSOR_DIR, RenderTask, render_support
from skt_lib.schemas import SUPPORTS
from stages._common import parse_args, run_items
from viz.render_views_report import log_views, write_report
from viz.report import write_metrics, write_run_log

log = logging.getLogger("render_views")


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

    clouds = log_views(out / "render_views.rrd", results, supports, src, out, p)
    write_report(rep, metrics, clouds, supports, p)
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
