"""Rerun logging: one entity tree for every stage.

    world/supports/<support_id>/mesh   support meshes (support frame)
    world/supports/<support_id>/cloud  partial point clouds
    world/supports/<support_id>/skt    semantic keypoint trajectories
    world/objects/<object_id>/mesh     object meshes (object frame)
    world/robot/...                    robot rollouts
    plots/<metric>                     scalars

Constant data is logged ``static=True``; each stage has its own timeline named after it.
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


def default_blueprint(title: str) -> rrb.Blueprint:
    return rrb.Blueprint(
        rrb.Spatial3DView(origin="world", name=title),
        collapse_panels=False,
    )


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
def recording(stage: str, path: str | Path, title: str) -> Iterator[rr.RecordingStream]:
    """A recording saved to ``path`` (atomically, on success only) with the default blueprint."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f".{path.name}.tmp")
    raw = path.with_name(f".{path.name}.raw")
    recording_id = f"{APP_ID}-{stage}"
    rec = rr.RecordingStream(APP_ID, recording_id=recording_id, send_properties=False,
                             batcher_config=_BATCHER)
    rec.set_log_time_enabled(False)
    rec.save(str(raw))
    rec.send_blueprint(fix_blueprint_ids(default_blueprint(title), stage))
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


def log_mesh(rec: rr.RecordingStream, entity: str, vertices: np.ndarray, faces: np.ndarray,
             rgba, translation=(0.0, 0.0, 0.0), pose: np.ndarray | None = None,
             **properties: str) -> None:
    """A static mesh at ``entity/mesh``; ``entity`` placed at ``pose`` (4×4) or else at
    ``translation`` (for galleries); properties shown in the selection panel and as a label."""
    if pose is not None:
        log_pose(rec, entity, pose)
    else:
        rec.log(entity, rr.Transform3D(translation=translation), static=True)
    rec.log(
        f"{entity}/mesh",
        rr.Mesh3D(vertex_positions=vertices.astype(np.float32),
                  triangle_indices=faces.astype(np.uint32), albedo_factor=list(rgba)),
        static=True,
    )
    if properties:
        rec.log(entity, rr.AnyValues(**properties), static=True)
        label = " ".join([entity.rsplit("/", 1)[-1], *properties.values()])
        top = [float(vertices[:, 0].mean()), 0.0, float(vertices[:, 2].max()) + 0.02]
        rec.log(f"{entity}/label", rr.Points3D([top], labels=[label], radii=0.001), static=True)


def log_pose(rec: rr.RecordingStream, entity: str, t: np.ndarray) -> None:
    """Place ``entity`` at the 4×4 pose ``t`` relative to its parent (static)."""
    rec.log(entity, rr.Transform3D(translation=t[:3, 3], mat3x3=t[:3, :3]), static=True)


def log_points(rec: rr.RecordingStream, entity: str, points, rgb=(230, 30, 30),
               radius: float = 0.003, labels=None) -> None:
    rec.log(entity, rr.Points3D(np.atleast_2d(points), colors=[rgb], radii=radius,
                                labels=labels), static=True)


def log_axes(rec: rr.RecordingStream, entity: str, origin, rotation, length: float = 0.03) -> None:
    """An x/y/z triad (red/green/blue) at ``origin`` with axes the columns of ``rotation``."""
    rec.log(entity, rr.Arrows3D(origins=[origin] * 3, vectors=(length * np.asarray(rotation).T),
                                colors=[(230, 40, 40), (40, 200, 40), (40, 80, 230)]), static=True)


def log_strip(rec: rr.RecordingStream, entity: str, points, rgb=(40, 110, 230)) -> None:
    """A static polyline (e.g. an SKT's keypoint path)."""
    rec.log(entity, rr.LineStrips3D([np.asarray(points)], colors=[rgb], radii=0.0008), static=True)


def log_camera(rec: rr.RecordingStream, entity: str, pose: np.ndarray, width: int, height: int,
               fov_deg: float) -> None:
    """A pinhole camera frustum at ``pose`` (camera-to-parent, OpenCV axes)."""
    log_pose(rec, entity, np.asarray(pose, dtype=np.float64))
    focal = float(0.5 * height / np.tan(np.radians(fov_deg) / 2))
    rec.log(entity, rr.Pinhole(focal_length=focal, width=width, height=height,
                               camera_xyz=rr.ViewCoordinates.RDF, image_plane_distance=0.03),
            static=True)


def log_colored_points(rec: rr.RecordingStream, entity: str, points, colors,
                       radius: float = 0.0008) -> None:
    """Static points with per-point RGB colours (uint8 (N, 3))."""
    rec.log(entity, rr.Points3D(np.asarray(points), colors=colors, radii=radius), static=True)


def log_scatter_2d(rec: rr.RecordingStream, entity: str, xy, class_ids, labels=None) -> None:
    """A static 2D scatter (e.g. ``plots/pca``) coloured by class id."""
    rec.log(entity, rr.Points2D(np.asarray(xy), class_ids=np.asarray(class_ids), radii=0.02,
                                labels=labels), static=True)
