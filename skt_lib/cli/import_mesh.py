"""``skt import-object MESH``: bring your own hangable object.

The mesh (any format trimesh reads) is scaled to metres (``--units``), repaired or refused
(:mod:`skt_lib.geometry.repair`), its hanging aperture found — the through-hole that admits
the largest rod (:mod:`skt_lib.geometry.aperture`; ``--aperture-point/--aperture-axis``
override it) — and moved into the object frame of docs/frames.md. CoACD splits it into
convex parts written in ``mesh_gen``'s compound-of-hulls format with a URDF; it is hung on
the test rod as ``contact_sim`` hangs objects, and its keypoint extracted as
``rotation_extraction`` does. The result lives in ``<data-root>/user/objects/<name>/``
and is written only once everything has passed.
"""

import os
import shutil
import sys
import tempfile
from pathlib import Path

import numpy as np
import trimesh

from skt_lib.cli.common import existing_file, progress
from skt_lib.config.params_file import load_params
from skt_lib.errors import InputError, MeshError
from skt_lib.geometry.aperture import find_aperture, object_frame
from skt_lib.geometry.build import OBJECT_RGBA
from skt_lib.geometry.checks import check_parts, check_solid
from skt_lib.geometry.convex import Mesh
from skt_lib.geometry.export import mass_properties, read_obj, write_shape
from skt_lib.geometry.objects import aperture_clearance
from skt_lib.geometry.decompose import decompose
from skt_lib.geometry.repair import UNITS, load_solid
from skt_lib.geometry.simplify import Simplified
from skt_lib.geometry.se3 import invert, matrix_to_quat, pose_matrix, transform_points
from skt_lib.io import write_json_atomic
from skt_lib.items import OBJECT_RECORD, user_dir
from skt_lib.sim.contact_sim import ROD_ARM, ROD_SITE, HangTask, simulate_hangs
from skt_lib.sim.keypoints import keypoint_from_hang

#: Below this IoU between the convex parts' union and the visual mesh, the import warns.
IOU_WARN = 0.9
EXAMPLE = """example:
  skt import-object my_mug.obj --name my_mug
  skt import-object part.stl --units mm --aperture-point 0 40 55 --aperture-axis 1 0 0"""


def import_parser(sub, kind: str, help: str, description: str, example: str):
    """The parser of ``skt import-<kind>`` with the options both import commands share."""
    ap = sub.add_parser(f"import-{kind}", help=help, description=description, epilog=example)
    ap.add_argument("mesh", help="OBJ, STL, PLY, GLB… (anything trimesh reads)")
    ap.add_argument("--name", help=f"name of the imported {kind} (default: the file's stem)")
    ap.add_argument("--units", choices=sorted(UNITS), default="m", help="units of the mesh")
    ap.add_argument("--params", default="params.yaml", help="params file (default: params.yaml)")
    ap.add_argument("--data-root", default="data", help="data folder (default: data)")
    return ap


def add_parser(sub) -> None:
    ap = import_parser(sub, "object", "import a hangable object mesh (finds its aperture)",
                       __doc__.splitlines()[0], EXAMPLE)
    ap.add_argument("--aperture-point", type=float, nargs=3, metavar=("X", "Y", "Z"),
                    help="centre of the hanging hole, mesh frame and units (with --aperture-axis)")
    ap.add_argument("--aperture-axis", type=float, nargs=3, metavar=("X", "Y", "Z"),
                    help="axis of the hanging hole, mesh frame")
    ap.set_defaults(run=run)


def _aperture(args, mesh: Mesh, seed: int) -> tuple[np.ndarray, np.ndarray]:
    if (args.aperture_point is None) != (args.aperture_axis is None):
        raise InputError("--aperture-point and --aperture-axis: give both or neither")
    if args.aperture_point is not None:
        axis = np.asarray(args.aperture_axis, float)
        if not np.isfinite(axis).all() or np.linalg.norm(axis) == 0:
            raise InputError(f"--aperture-axis: not a direction: {args.aperture_axis}")
        return np.asarray(args.aperture_point, float) * UNITS[args.units], axis / np.linalg.norm(axis)
    surface = np.asarray(trimesh.sample.sample_surface_even(mesh.to_trimesh(), 4000, seed=seed)[0])
    found = find_aperture(mesh, surface)
    if found is None:
        raise MeshError(f"{args.mesh}: no through-hole that a rod can pass (nothing to hang it by)")
    return found.point, found.axis


def import_object(args, params, bar) -> dict:
    name, cs = args.name, params.contact_sim
    solid = load_solid(args.mesh, args.units)
    mesh = solid.mesh
    bar.update()
    point, axis = _aperture(args, mesh, params.common.seed)
    _, com, _ = mass_properties(mesh, params.mesh_gen.density_kg_m3)
    try:
        frame = object_frame(point, axis, com)
    except ValueError as err:
        raise MeshError(f"{args.mesh}: {err}") from None
    to_object = invert(frame)
    visual = Mesh(transform_points(to_object, mesh.vertices), mesh.faces)
    bar.update()
    # decomposed in the author's frame (CoACD's voxels are axis-aligned: the author's axes
    # usually follow the shape), then moved rigidly: hulls stay convex
    hulls, route = decompose(mesh, seed=params.common.seed)
    parts = [Mesh(transform_points(to_object, h.vertices), h.faces) for h in hulls]
    iou = check_parts(parts, visual, str(args.mesh), min_iou=0.0)
    clearance = aperture_clearance(parts)
    if clearance < cs.rod_radius_m:
        raise MeshError(f"{args.mesh}: its aperture admits a rod of radius "
                        f"{1000 * clearance:.1f} mm, the test rod (contact_sim.rod_radius_m) is "
                        f"{1000 * cs.rod_radius_m:.1f} mm")
    bar.update()
    with tempfile.TemporaryDirectory(prefix="skt-import-") as tmp:
        mass, com, inertia = mass_properties(visual, params.mesh_gen.density_kg_m3)
        paths = write_shape(Path(tmp), name, visual, parts, mass, com, inertia, OBJECT_RGBA["other"])
        check_solid(read_obj(paths["mesh"])[0], f"{args.mesh} (written)")
        row = simulate_hangs(HangTask(name, "object_on_rod", name, str(paths["urdf"]), clearance,
                                      "", "", ROD_ARM, ROD_SITE, cs.rod_radius_m,
                                      params.common.seed, cs))
        bar.update()
        if not row["ok"]:
            raise MeshError(f"{args.mesh}: does not hang on the test rod ({row['failure_reason']}; "
                            f"{row['n_success']}/{row['n_attempts']} drops hung)")
        kp = keypoint_from_hang(pose_matrix(row["hang_position"], row["hang_quat"]),
                                row["contact_object"], params.rotation_extraction.front_offset_m)
        record = {
            "name": name, "kind": "object", "source": str(args.mesh), "units": args.units,
            "object_from_source": invert(frame).tolist(),
            "aperture_point_source": point.tolist(), "aperture_axis_source": axis.tolist(),
            "aperture_clearance_m": clearance, **mesh_record(solid, parts, route, iou),
            "mass_kg": mass,
            "keypoint": pose_matrix(kp.position, matrix_to_quat(kp.rotation)).ravel().tolist(),
            "contact_object": list(row["contact_object"]),
        }
        write_json_atomic(Path(tmp) / OBJECT_RECORD, record)
        _move_into_place(Path(tmp), user_dir(args.data_root, "object", name))
    bar.update()
    return record


def mesh_record(solid: Simplified, parts, route: str, iou: float) -> dict:
    """What an import record says of the mesh: its faces as read and as used, the
    simplification's method and measured Hausdorff distance, the decomposition route."""
    return {"n_faces_source": solid.faces_before, "n_faces": len(solid.mesh.faces),
            "simplified_by": solid.method, "simplify_hausdorff_m": solid.hausdorff_m,
            "decomposition": route, "n_parts": len(parts), "part_iou": iou}


def _move_into_place(tmp: Path, dest: Path) -> None:
    """Copy the finished folder next to ``dest`` and rename it into place (all or nothing)."""
    dest.parent.mkdir(parents=True, exist_ok=True)
    staging = dest.parent / f".{dest.name}.tmp"
    shutil.rmtree(staging, ignore_errors=True)
    try:
        shutil.copytree(tmp, staging)
        os.replace(staging, dest)
    finally:
        shutil.rmtree(staging, ignore_errors=True)


def new_import(kind: str, mesh, name: str | None, data_root) -> tuple[str, Path]:
    """(name, destination folder) of importing ``mesh`` as a ``kind`` ("support", "object"),
    or :class:`InputError`: no such file, a bad name, or one already imported."""
    existing_file(mesh, "mesh")
    name = name or Path(mesh).stem
    if not name.replace("_", "").replace("-", "").isalnum():
        raise InputError(f"--name: {name!r} must be letters, digits, '_' or '-'")
    dest = user_dir(data_root, kind, name)
    if dest.exists():
        raise InputError(f"{dest}: {'an' if kind == 'object' else 'a'} {kind} named {name!r} is "
                         "already imported (choose another --name or delete the folder)")
    return name, dest


def run_import(args, kind: str, do_import) -> tuple[Path, dict]:
    """The import commands' common part: checks, params, ``do_import(args, params, bar)``
    under a progress bar, the IoU warning; (destination, record)."""
    args.name, dest = new_import(kind, args.mesh, args.name, args.data_root)
    params = load_params(args.params)
    with progress(5, f"import-{kind}") as bar:
        record = do_import(args, params, bar)
    if record["part_iou"] < IOU_WARN:
        sys.stderr.write(f"WARNING: {args.mesh}: convex parts cover the mesh with IoU "
                         f"{record['part_iou']:.3f} < {IOU_WARN}: collisions will be coarse\n")
    return dest, record


def run(args) -> int:
    dest, record = run_import(args, "object", import_object)
    print(f"{dest}: imported {args.name} ({record['n_parts']} convex parts, IoU "
          f"{record['part_iou']:.3f}, aperture admits a {1000 * record['aperture_clearance_m']:.1f} "
          f"mm rod, {1000 * record['mass_kg']:.0f} g); hang it with "
          f"`skt hang --object {args.name}`")
    return 0
