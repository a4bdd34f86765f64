"""render_views' Rerun recording (a few supports per level: the mesh, every 7th view's cloud
and camera) and report (counts, the sensor views' figures, sample partial clouds)."""

from pathlib import Path

from skt_lib.config import LEVELS
from skt_lib.config.render_views import RenderViewsParams
from skt_lib.geometry.build import SUPPORT_RGBA
from skt_lib.geometry.export import read_obj
from skt_lib.io import read_npz
from skt_lib.perception.views import RENDER_SPEC, SENSOR_DIR
from viz.figures import cloud_grid
from viz.report import Report
from viz.rerun_log import (SUPPORT_EYE, SUPPORT_LOOK_AT, ItemTimeline, item_blueprint, log_camera,
                           log_mesh, log_points, recording, support_path)

REVIEW_PER_LEVEL = 2  # supports per difficulty level in the recording
VIEW_RGB = [(60, 120, 220), (220, 90, 40), (40, 170, 90), (200, 60, 170), (200, 180, 40),
            (60, 190, 200)]


def log_views(path: Path, results: list[dict], supports, src: Path, out: Path,
              p: RenderViewsParams) -> dict:
    """The recording at ``path``: :data:`REVIEW_PER_LEVEL` rendered supports per level
    (``results`` of :func:`~skt_lib.perception.views.render_support`, ``supports`` the supports
    table, meshes under ``src``, views under ``out``); returns the sample's clouds by id."""
    n_views = p.n_azimuth * p.n_elevation
    done = {r["support_id"]: r for r in results}
    level = supports.set_index("support_id")
    sample = [s for lv in LEVELS
              for s in [s for s in level.index[level["difficulty"] == lv] if s in done][:REVIEW_PER_LEVEL]]
    clouds = {sid: read_npz(out / f"{sid}.npz", RENDER_SPEC) for sid in sample}
    bp = item_blueprint("render_views: partial clouds (every 7th view)", "support", SUPPORT_EYE,
                        SUPPORT_LOOK_AT)
    with recording("render_views", path, "render_views", bp) as rec:
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
    return clouds


def write_report(rep: Path, metrics: dict, clouds: dict, supports, p: RenderViewsParams) -> None:
    """``reports/render_views/report.md`` and ``views.png`` from the stage's ``metrics`` and
    the recorded sample's ``clouds`` (:func:`log_views`)."""
    n_views, sensor = metrics["views_per_support"], metrics.get("sensor_views")
    report = Report("render_views", rep)
    report.text(f"{metrics['n_rendered']} of {metrics['n_supports']} supports rendered (failed: "
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
    level = supports.set_index("support_id")["difficulty"]
    first = list({level[sid]: sid for sid in reversed(list(clouds))}.values())[::-1]
    cloud_grid([(f"{sid} view {v}", clouds[sid]["points"][v], None) for sid in first for v in (0, 17, 41)
                if v < n_views], report.figure("views.png", "Sample partial clouds (one support per "
                                                "level; views 0, 17, 41)"), ncols=3)
    report.recording("support")
    report.write()
