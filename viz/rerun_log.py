"""Rerun logging: one entity tree for every stage.

    world/supports/<support_id>/mesh   support meshes (support frame)
    world/supports/<support_id>/cloud  partial point clouds
    world/supports/<support_id>/skt    semantic keypoint trajectories
    world/objects/<object_id>/mesh     object meshes (object frame)
    world/robot/...                    robot rollouts
    item/info                          the current item's label and numbers (markdown)
    plots/<metric>                     scalars, one per item or per step

Per-item stages show **one item at a time**: item k is logged at time k of a sequence
timeline named for what the items are (``support``, ``object``, ``trial``), at the origin of
its own frame, and cleared when item k + 1 starts (:class:`ItemTimeline`); the viewer's
scrubber steps from item to item. Each stage's blueprint frames the 3D view on the item and
shows its label and plots beside it (:func:`item_blueprint`).

Recordings are written to a temporary file, made byte-reproducible (:mod:`viz.stable_rrd`)
and renamed when complete.
"""

import itertools
import os
import uuid
from collections.abc import Iterator
from contextlib import contextmanager
from datetime import timedelta
from pathlib import Path

import numpy as np
import rerun as rr
import rerun.blueprint as rrb

from viz.stable_rrd import stabilise

APP_ID = "skt_hang"
# Chunks are cut by size only (no wall-clock flush tick), so their contents depend on what
# was logged, not on timing; viz.stable_rrd then fixes ids and order (byte-stable files).
_BATCHER = rr.ChunkBatcherConfig(flush_tick=timedelta(days=1), flush_num_bytes=8 << 20)


def support_path(support_id: str) -> str:
    return f"world/supports/{support_id}"


def object_path(object_id: str) -> str:
    return f"world/objects/{object_id}"


INFO = "item/info"
# Review cameras (support frame, metres): a support spans about x ∈ [0, 0.12], |y|, |z| < 0.08;
# its SKTs reach ~0.2 m out of the wall. Objects (object frame) hang from the origin toward −z.
SUPPORT_EYE, SUPPORT_LOOK_AT = (0.16, -0.13, 0.085), (0.05, 0.0, -0.005)
SKT_EYE, SKT_LOOK_AT = (0.27, -0.22, 0.15), (0.08, 0.0, 0.0)
OBJECT_EYE, OBJECT_LOOK_AT = (0.20, -0.22, 0.04), (0.0, 0.0, -0.05)
#: One colormap for affordance values in [0, 1] wherever they are drawn.
AFFORDANCE_CMAP = "plasma"
#: One colour per evaluated method (RGB), in the 3D views and plots of sim_eval.
METHOD_RGB = {"oracle": (40, 160, 70), "oracle_floating": (120, 200, 120),
              "template_only": (230, 160, 30), "sctdn": (220, 50, 50), "kpam": (60, 110, 220)}


def default_blueprint(title: str) -> rrb.Blueprint:
    return rrb.Blueprint(
        rrb.Spatial3DView(origin="world", name=title),
        collapse_panels=False,
    )


def item_blueprint(title: str, timeline: str, eye, look_at, side: tuple = ()) -> rrb.Blueprint:
    """A review layout: the 3D view (camera at ``eye`` looking at ``look_at``, +z up) beside
    the current item's label and the ``side`` views, the time panel on ``timeline``."""
    view = rrb.Spatial3DView(
        origin="world", name=title,
        eye_controls=rrb.EyeControls3D(position=eye, look_target=look_at, eye_up=(0.0, 0.0, 1.0)))
    right = rrb.Vertical(rrb.TextDocumentView(origin=INFO, name="item"), *side)
    return rrb.Blueprint(rrb.Horizontal(view, right, column_shares=[3, 1]),
                         rrb.BlueprintPanel(state="collapsed"),
                         rrb.SelectionPanel(state="collapsed"),
                         rrb.TimePanel(state="collapsed", timeline=timeline))


class ItemTimeline:
    """Items shown one at a time on the sequence timeline ``name``.

    :meth:`next` starts item k at time k: it clears (recursively) the entity roots of the
    previous item and writes the item's label to ``item/info``. Everything logged until the
    next call belongs to item k; log it non-static. The last item is never cleared, so the
    viewer, which opens at the end of the timeline, shows it."""

    def __init__(self, rec: rr.RecordingStream, name: str):
        self.rec, self.name, self.k = rec, name, -1
        self._roots: list[str] = []

    def next(self, roots: list[str] | str, title: str, times: dict[str, int] | None = None,
             **fields) -> int:
        """Start the next item; ``times``: other sequence timelines to set with it (the clear
        of the previous item is then on them too)."""
        self.k += 1
        self.rec.reset_time()
        self.rec.set_time(self.name, sequence=self.k)
        for name, value in (times or {}).items():
            self.rec.set_time(name, sequence=value)
        for root in self._roots:
            self.rec.log(root, rr.Clear(recursive=True))
        self._roots = [roots] if isinstance(roots, str) else list(roots)
        self.rec.log(INFO, rr.TextDocument(item_markdown(title, fields),
                                           media_type=rr.MediaType.MARKDOWN))
        return self.k

    def scalar(self, name: str, value: float) -> None:
        """``plots/<name>`` at the current item (a plot over items)."""
        self.rec.log(f"plots/{name}", rr.Scalars(float(value)))


def item_markdown(title: str, fields: dict) -> str:
    rows = "\n".join(f"| {k.replace('_', ' ')} | {_fmt(v)} |" for k, v in fields.items())
    return f"# {title}\n\n| | |\n|---|---|\n{rows}\n" if fields else f"# {title}\n"


def _fmt(v) -> str:
    return f"{v:.4g}" if isinstance(v, float) else str(v)


def affordance_colors(values) -> np.ndarray:
    """uint8 (N, 3) colours of affordance values in [0, 1] (:data:`AFFORDANCE_CMAP`)."""
    from matplotlib import colormaps

    v = np.clip(np.asarray(values, dtype=np.float64), 0.0, 1.0)
    return (colormaps[AFFORDANCE_CMAP](v)[:, :3] * 255).astype(np.uint8)


def fix_blueprint_ids(blueprint: rrb.Blueprint, name: str) -> rrb.Blueprint:
    """Give the blueprint's containers and views ids derived from ``name`` and their place in
    the tree instead of random ``uuid4``s (byte-reproducible recordings)."""
    counter = itertools.count()

    def visit(node) -> None:
        node.id = uuid.uuid5(uuid.NAMESPACE_URL, f"skt_hang/{name}/{next(counter)}")
        if isinstance(node, rrb.Container):
            for child in node.contents:
                visit(child)

    if hasattr(blueprint, "root_container"):
        visit(blueprint.root_container)
    return blueprint


@contextmanager
def recording(stage: str, path: str | Path, title: str,
              blueprint: rrb.Blueprint | None = None) -> Iterator[rr.RecordingStream]:
    """A recording saved to ``path`` (atomically, on success only) with ``blueprint`` (else
    a plain 3D view named ``title``)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp")
    raw = path.with_name(f".{path.name}.raw")
    recording_id = f"{APP_ID}-{stage}"
    rec = rr.RecordingStream(APP_ID, recording_id=recording_id, send_properties=False,
                             batcher_config=_BATCHER)
    rec.set_log_time_enabled(False)
    rec.save(str(raw))
    rec.send_blueprint(fix_blueprint_ids(blueprint or default_blueprint(title), stage))
    try:
        yield rec
        rec.flush()
        rec.disconnect()
        stabilise(raw, tmp, APP_ID, recording_id)
        os.replace(tmp, path)
    finally:
        for leftover in (raw, tmp):
            if leftover.exists():
                leftover.unlink()


# The log_* helpers log item data (non-static, at the current item's time) unless
# ``static=True`` (constant data shown at every time).


def log_mesh(rec: rr.RecordingStream, entity: str, vertices: np.ndarray, faces: np.ndarray,
             rgba, translation=(0.0, 0.0, 0.0), pose: np.ndarray | None = None,
             static: bool = False, **properties: str) -> None:
    """A mesh at ``entity/mesh``; ``entity`` placed at ``pose`` (4×4) or else at
    ``translation``; properties shown in the selection panel and as a label above it."""
    if pose is not None:
        log_pose(rec, entity, pose, static=static)
    else:
        rec.log(entity, rr.Transform3D(translation=translation), static=static)
    rec.log(
        f"{entity}/mesh",
        rr.Mesh3D(vertex_positions=vertices.astype(np.float32),
                  triangle_indices=faces.astype(np.uint32), albedo_factor=list(rgba)),
        static=static,
    )
    if properties:
        rec.log(entity, rr.AnyValues(**properties), static=static)
        label = " ".join([entity.rsplit("/", 1)[-1], *properties.values()])
        top = [float(vertices[:, 0].mean()), 0.0, float(vertices[:, 2].max()) + 0.02]
        rec.log(f"{entity}/label", rr.Points3D([top], labels=[label], radii=0.001), static=static)


def log_pose(rec: rr.RecordingStream, entity: str, t: np.ndarray, static: bool = False) -> None:
    """Place ``entity`` at the 4×4 pose ``t`` relative to its parent."""
    rec.log(entity, rr.Transform3D(translation=t[:3, 3], mat3x3=t[:3, :3]), static=static)


def log_points(rec: rr.RecordingStream, entity: str, points, rgb=(230, 30, 30),
               radius: float = 0.003, labels=None, static: bool = False) -> None:
    rec.log(entity, rr.Points3D(np.atleast_2d(points), colors=[rgb], radii=radius,
                                labels=labels), static=static)


def log_axes(rec: rr.RecordingStream, entity: str, origin, rotation, length: float = 0.03,
             static: bool = False) -> None:
    """An x/y/z triad (red/green/blue) at ``origin`` with axes the columns of ``rotation``."""
    rec.log(entity, rr.Arrows3D(origins=[origin] * 3, vectors=(length * np.asarray(rotation).T),
                                colors=[(230, 40, 40), (40, 200, 40), (40, 80, 230)]),
            static=static)


def log_frames(rec: rr.RecordingStream, entity: str, frames, length: float = 0.01,
               static: bool = False) -> None:
    """Many x/y/z triads (4×4 ``frames``) as one batch of arrows (e.g. an SKT's waypoints)."""
    frames = np.asarray(frames)
    origins = np.repeat(frames[:, :3, 3], 3, axis=0)
    vectors = length * np.swapaxes(frames[:, :3, :3], 1, 2).reshape(-1, 3)
    colors = np.tile([(230, 40, 40), (40, 200, 40), (40, 80, 230)], (len(frames), 1))
    rec.log(entity, rr.Arrows3D(origins=origins, vectors=vectors, colors=colors), static=static)


def log_strip(rec: rr.RecordingStream, entity: str, points, rgb=(40, 110, 230),
              radius: float = 0.0008, static: bool = False) -> None:
    """A polyline (e.g. an SKT's keypoint path)."""
    rec.log(entity, rr.LineStrips3D([np.asarray(points)], colors=[rgb], radii=radius),
            static=static)


def log_camera(rec: rr.RecordingStream, entity: str, pose: np.ndarray, width: int, height: int,
               fov_deg: float, static: bool = False) -> None:
    """A pinhole camera frustum at ``pose`` (camera-to-parent, OpenCV axes)."""
    log_pose(rec, entity, np.asarray(pose, dtype=np.float64), static=static)
    focal = float(0.5 * height / np.tan(np.radians(fov_deg) / 2))
    rec.log(entity, rr.Pinhole(focal_length=focal, width=width, height=height,
                               camera_xyz=rr.ViewCoordinates.RDF, image_plane_distance=0.03),
            static=static)


def log_colored_points(rec: rr.RecordingStream, entity: str, points, colors,
                       radius: float = 0.0008, static: bool = False) -> None:
    """Points with per-point RGB colours (uint8 (N, 3))."""
    rec.log(entity, rr.Points3D(np.asarray(points), colors=colors, radii=radius), static=static)


def log_scatter_2d(rec: rr.RecordingStream, entity: str, xy, class_ids, labels=None,
                   static: bool = False) -> None:
    """A 2D scatter (e.g. ``plots/pca``) coloured by class id."""
    rec.log(entity, rr.Points2D(np.asarray(xy), class_ids=np.asarray(class_ids), radii=0.02,
                                labels=labels), static=static)
