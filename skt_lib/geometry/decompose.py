"""Convex decomposition of a user's mesh, by routes that a native crash cannot end.

CoACD (approximate convex decomposition) aborts the process on some meshes (an assertion
in its remesher) and can run long; PyBullet's V-HACD is the second opinion. Each route
runs in a child process under a time limit (:mod:`skt_lib.isolated`), in this order
(:data:`ROUTES`):

1. ``coacd``: CoACD on the mesh as repaired (a checked closed solid), its own remeshing
   off — CoACD's manifold check calls the slivers of an exact boolean union
   "self-intersections" and would voxelize the mesh at 1/50 of its size (a peg and knob
   written as two bodies came out 1 mm fat, IoU 0.82 against 0.998 without);
2. ``coacd_remeshed``: CoACD's own remeshing on, the next seed;
3. ``vhacd``: PyBullet's V-HACD (voxel based: no remesher to trip).

The first route whose parts are convex solids covering the mesh with IoU ≥
:data:`MIN_IOU` wins; if none reaches it, the best that returned parts. Only when every
route fails is the mesh refused, with what each route said. The parts are hulls
(:func:`skt_lib.geometry.convex.hull`) in the mesh's frame.
"""

import logging
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial import QhullError

from skt_lib.errors import MeshError
from skt_lib.geometry.checks import check_parts
from skt_lib.geometry.convex import Mesh, hull
from skt_lib.isolated import ChildFailed, call_isolated

log = logging.getLogger(__name__)
#: Seconds each route may take before it is stopped and the next one tried.
TIME_LIMIT_S = 90.0
#: A route whose parts cover the mesh with a lower IoU is passed over for the next.
MIN_IOU = 0.9


@dataclass(frozen=True)
class Route:
    """One way to decompose: ``target`` (``module:function`` run in a child), the seed
    offset, and the target's options."""

    name: str
    target: str
    seed_offset: int = 0
    options: tuple[tuple[str, object], ...] = ()


ROUTES = (
    Route("coacd", f"{__name__}:coacd_parts", options=(("remesh", False),)),
    Route("coacd_remeshed", f"{__name__}:coacd_parts", 1, (("remesh", True),)),
    Route("vhacd", f"{__name__}:vhacd_parts"),
)


def _packed(parts) -> dict[str, np.ndarray]:
    parts = [np.asarray(v, dtype=np.float64).reshape(-1, 3) for v in parts]
    return {"points": np.concatenate(parts) if parts else np.zeros((0, 3)),
            "counts": np.array([len(v) for v in parts], dtype=np.int64)}


def coacd_parts(vertices, faces, threshold: float, seed: int, remesh: bool
                ) -> dict[str, np.ndarray]:
    """CoACD's convex parts of a mesh (child side): their vertices, packed. ``remesh``:
    CoACD's preprocessing "auto" (remeshes what its check calls non-manifold), else off."""
    import coacd

    coacd.set_log_level("error")
    parts = coacd.run_coacd(coacd.Mesh(vertices, faces), threshold=threshold, seed=seed,
                            preprocess_mode="auto" if remesh else "off",
                            max_ch_vertex=64, mcts_iterations=60, mcts_nodes=10,
                            mcts_max_depth=2)  # a third of the default search: ~5 s a mug
    return _packed([v for v, _ in parts])


def vhacd_parts(vertices, faces, threshold: float, seed: int) -> dict[str, np.ndarray]:
    """PyBullet V-HACD's convex parts of a mesh (child side): their vertices, packed.
    Deterministic (no seed); ``threshold`` is CoACD's and does not apply."""
    import pybullet as pb

    with tempfile.TemporaryDirectory(prefix="skt-vhacd-") as tmp:
        src, dst, logf = (str(Path(tmp) / n) for n in ("in.obj", "out.obj", "log.txt"))
        lines = [f"v {x:.9f} {y:.9f} {z:.9f}" for x, y, z in vertices]
        lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
        Path(src).write_text("\n".join(lines) + "\n")
        pb.vhacd(src, dst, logf, resolution=400000, maxNumVerticesPerCH=64)
        parts, current = [], []
        for line in Path(dst).read_text().splitlines():
            if line.startswith("o ") and current:
                parts.append(current)
                current = []
            elif line.startswith("v "):
                current.append([float(x) for x in line.split()[1:4]])
        if current:
            parts.append(current)
    return _packed(parts)


def _hulls(out: dict[str, np.ndarray]) -> list[Mesh]:
    hulls = []
    for v in np.split(out["points"], np.cumsum(out["counts"])[:-1]):
        try:
            hulls.append(hull(v))
        except (ValueError, QhullError):
            continue  # a flat sliver (fewer than 4 points, or no volume): nothing to collide with
    return hulls


def decompose(mesh: Mesh, threshold: float = 0.05, seed: int = 0, routes=ROUTES,
              time_limit_s: float = TIME_LIMIT_S) -> tuple[list[Mesh], str]:
    """Convex parts covering ``mesh`` and the name of the route that made them (see the
    module docstring), or :class:`MeshError` naming what every route said."""
    tried, best = [], None
    for route in routes:
        try:
            out = call_isolated(route.target, {"vertices": mesh.vertices, "faces": mesh.faces},
                                {"threshold": threshold, "seed": seed + route.seed_offset,
                                 **dict(route.options)}, time_limit_s)
            hulls = _hulls(out)
            if not hulls:
                raise MeshError("no parts")
            iou = check_parts(hulls, mesh, route.name, min_iou=0.0)
        except (ChildFailed, MeshError) as err:
            tried.append(f"{route.name}: {err}")
            log.warning("convex decomposition: %s failed (%s); trying the next route",
                        route.name, err)
            continue
        if iou >= MIN_IOU:
            return hulls, route.name
        tried.append(f"{route.name}: IoU {iou:.3f}")
        if best is None or iou > best[0]:
            best = (iou, hulls, route.name)
    if best is not None:
        return best[1], best[2]
    raise MeshError("convex decomposition failed by every route (" + "; ".join(tried) + ")")
