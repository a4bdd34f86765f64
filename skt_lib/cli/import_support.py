"""``skt import-support MESH``: bring your own hook, peg or rack.

The mesh (any format trimesh reads) is scaled to metres (``--units``), repaired or refused
(:mod:`skt_lib.geometry.repair`) and put in the support frame (docs/design.md §3: origin at the
mount point on the wall, +x out of the wall, +z up): as it is, or by ``--mount`` and
``--out-axis`` (the mesh's +z stays up as far as the out-axis allows). A mesh that reaches
behind the wall is refused; one that does not touch the wall gets a wall plate
(:data:`PLATE_HALF_Y_M`, 1 cm thick, 2.5 cm beyond its wall end up and down). A mesh above
the face budget is simplified first (:mod:`skt_lib.geometry.simplify`). Then the
pipeline's own per-item code, not a copy: convex parts (:mod:`skt_lib.geometry.decompose`:
CoACD, or V-HACD where CoACD fails) and a URDF as ``mesh_gen`` writes them, the arms and
difficulty level from the mesh (:func:`skt_lib.geometry.centreline.hang_candidates`), the
reference object's hang as ``contact_sim`` drops it and SKTs planned and re-checked as
``rrt_skts`` does — on the first arm where both succeed (a fork's or rack's prongs are
tried in turn; ``--arm`` picks one) — and the 42 views of ``render_views``. The result
lives in ``<data-root>/user/supports/<name>/`` and is written only once everything has
passed.
"""

import tempfile
from pathlib import Path

import numpy as np

from skt_lib.cli.import_mesh import _move_into_place, import_parser, mesh_record, run_import
from skt_lib.errors import InputError, MeshError
from skt_lib.geometry.build import SUPPORT_RGBA
from skt_lib.geometry.centreline import hang_candidates
from skt_lib.geometry.checks import check_parts, check_solid
from skt_lib.geometry.convex import Mesh, box, union
from skt_lib.geometry.export import read_obj, write_shape
from skt_lib.geometry.decompose import decompose
from skt_lib.geometry.repair import UNITS, load_solid
from skt_lib.geometry.se3 import pose_matrix, transform_points
from skt_lib.geometry.skt import arc_length
from skt_lib.geometry.supports import PLATE_THICKNESS_M
from skt_lib.io import read_table, write_json_atomic
from skt_lib.items import SUPPORT_RECORD, user_dir
from skt_lib.perception.views import RenderTask, render_support
from skt_lib.planning.skts import REACH_TOL_M, SktTask, load_probe_objects, plan_support_skts
from skt_lib.schemas import OBJECTS
from skt_lib.sim.contact_sim import HangTask, eval_damping, simulate_hangs

#: Half-width (m, along y) of the wall plate added to a mesh that does not touch the wall.
PLATE_HALF_Y_M = 0.02
#: A mesh may reach this far behind the wall plane (x < 0) before it is refused (m).
WALL_TOL_M = 0.001
#: Supporting items larger or smaller than these (m, largest extent) are refused as mis-scaled.
SIZE_M = (0.02, 1.0)
EXAMPLE = """example:
  skt import-support my_hook.stl --units mm
  skt import-support hook.obj --name coat_hook --mount 0 0 0.05 --out-axis 0 -1 0"""


def add_parser(sub) -> None:
    ap = import_parser(sub, "support", "import a hook/peg/rack mesh (plans its SKTs)",
                       __doc__.splitlines()[0], EXAMPLE)
    ap.add_argument("--mount", type=float, nargs=3, metavar=("X", "Y", "Z"),
                    help="mount point on the wall, mesh frame and units (with --out-axis)")
    ap.add_argument("--out-axis", type=float, nargs=3, metavar=("X", "Y", "Z"),
                    help="direction out of the wall, mesh frame (with --mount)")
    ap.add_argument("--arm", type=int, help="which arm to hang on (default: the lowest)")
    ap.set_defaults(run=run)


def support_frame(args) -> np.ndarray:
    """4×4 transform from the mesh's frame (metres) into the support frame."""
    if (args.mount is None) != (args.out_axis is None):
        raise InputError("--mount and --out-axis: give both or neither")
    if args.mount is None:
        return np.eye(4)
    x = np.asarray(args.out_axis, float)
    if not np.isfinite(x).all() or np.linalg.norm(x) == 0:
        raise InputError(f"--out-axis: not a direction: {args.out_axis}")
    x /= np.linalg.norm(x)
    z = np.array([0.0, 0.0, 1.0]) - x[2] * x
    if np.linalg.norm(z) < 1e-6:
        raise InputError("--out-axis: points straight up or down; a wall is vertical")
    z /= np.linalg.norm(z)
    rot = np.stack([x, np.cross(z, x), z])  # rows: the support axes in the mesh frame
    t = np.eye(4)
    t[:3, :3] = rot
    t[:3, 3] = -rot @ (np.asarray(args.mount, float) * UNITS[args.units])
    return t


def mount(mesh: Mesh, name: str) -> tuple[Mesh, bool]:
    """``mesh`` (support frame) checked against the wall, with a plate added if it has none;
    (mesh, whether a plate was added)."""
    v = mesh.vertices
    if v[:, 0].min() < -WALL_TOL_M:
        raise MeshError(f"{name}: reaches {1000 * -v[:, 0].min():.1f} mm behind the wall (x < 0): "
                        "check --mount/--out-axis")
    extent = float((v.max(0) - v.min(0)).max())
    if not SIZE_M[0] <= extent <= SIZE_M[1]:
        raise MeshError(f"{name}: {extent:.3g} m across; a supporting item is "
                        f"{SIZE_M[0]}–{SIZE_M[1]} m (wrong --units?)")
    if v[:, 0].min() <= WALL_TOL_M:
        return mesh, False
    near = v[v[:, 0] <= PLATE_THICKNESS_M]
    if not len(near):
        raise MeshError(f"{name}: its nearest point is {1000 * v[:, 0].min():.1f} mm in front of "
                        "the wall; it must reach the plate "
                        f"(x ≤ {1000 * PLATE_THICKNESS_M:.0f} mm)")
    z_lo, z_hi = near[:, 2].min() - 0.025, near[:, 2].max() + 0.025
    plate = box([PLATE_THICKNESS_M / 2, 0.0, (z_lo + z_hi) / 2],
                [PLATE_THICKNESS_M / 2, PLATE_HALF_Y_M, (z_hi - z_lo) / 2])
    return union([mesh, plate]), True


def _reference(root: Path):
    mg = root / "mesh_gen"
    objects = read_table(mg / "objects.parquet", OBJECTS)
    ref = objects[objects["is_reference"]].iloc[0]
    reference, train, _ = load_probe_objects(root)
    return ref, reference, train


def _hang_and_plan(args, params, paths, root: Path, candidates, arms, bar, plan):
    """(difficulty, arm index, hang, SKTs) on the first candidate arm where the reference
    object hangs as ``contact_sim`` drops it and an SKT planned as ``rrt_skts`` plans reaches
    that hang (``plan``: :func:`plan_support_skts`); or :class:`MeshError` naming what each
    arm gave."""
    ref_row, reference, train = _reference(root)
    seed, tried = params.common.seed, []
    for diff, arm in candidates:
        k = next(i for i, a in enumerate(arms) if a is arm)
        hang = simulate_hangs(HangTask(
            args.name, "reference_on_support", ref_row.object_id,
            str(root / "mesh_gen" / ref_row.urdf_path), ref_row.aperture_clearance_m, args.name,
            str(paths["urdf"]), tuple(map(tuple, arm.points)), tuple(diff.hang_point), arm.radius,
            seed, params.contact_sim, eval_damping(params)))
        if not hang["ok"]:
            tried.append(f"arm {k}: the reference object does not hang on it "
                         f"({hang['failure_reason']}; {hang['n_success']}/{hang['n_attempts']} "
                         "drops hung)")
            continue
        bar.update()
        planned = plan(SktTask(
            args.name, "user", str(paths["urdf"]), str(paths["mesh"]), reference, train, (),
            tuple(hang["hang_position"]), tuple(hang["hang_quat"]), seed, params.clustering.T,
            params.rrt_skts))
        goal = (pose_matrix(hang["hang_position"], hang["hang_quat"])
                @ np.asarray(reference.keypoint).reshape(4, 4))[:3, 3]
        skts = [s for s in planned["skts"]
                if np.linalg.norm(s["keypoints"][0] - goal) <= REACH_TOL_M]
        if skts:
            return diff, k, hang, planned, skts
        tried.append(f"arm {k}: no SKT reaches the hang ({planned['n_attempted']} attempts; "
                     f"failures {planned['failures'] or 'none'})")
    raise MeshError(f"{args.mesh}: " + "; ".join(tried))


def import_support(args, params, bar, plan=plan_support_skts) -> dict:
    """The imported support's record (module notes); ``plan(task) -> planned`` plans an arm's
    SKTs (:func:`plan_support_skts`; ``tools/route_room.py`` hands in its own, to measure
    the task an arm gives the planner)."""
    name, seed, root = args.name, params.common.seed, Path(args.data_root)
    to_support = support_frame(args)
    solid = load_solid(args.mesh, args.units)
    mesh = Mesh(transform_points(to_support, solid.mesh.vertices), solid.mesh.faces)
    visual, plated = mount(mesh, str(args.mesh))
    parts, route = decompose(visual, seed=seed)
    bar.update()
    candidates, arms = hang_candidates(visual, params.mesh_gen, args.arm)
    bar.update()
    with tempfile.TemporaryDirectory(prefix="skt-import-") as tmp:
        paths = write_shape(Path(tmp), name, visual, parts, 0.0, [0, 0, 0], [[0] * 3] * 3,
                            SUPPORT_RGBA)
        (visual_back,) = read_obj(paths["mesh"])
        check_solid(visual_back, f"{args.mesh} (written)")
        iou = check_parts(read_obj(paths["collision"]), visual_back, f"{args.mesh} (written)",
                          min_iou=0.0)
        diff, arm, hang, planned, skts = _hang_and_plan(args, params, paths, root, candidates,
                                                        arms, bar, plan)
        bar.update()
        render_support(RenderTask(name, str(paths["mesh"]), str(Path(tmp) / "views.npz"), seed,
                                  params.render_views))
        record = {
            "name": name, "kind": "support", "source": str(args.mesh), "units": args.units,
            "support_from_source": to_support.tolist(), "plate_added": plated,
            "difficulty": diff.level, "blocking_height_m": diff.blocking_height_m,
            "clearance_above_m": diff.clearance_above_m, "tip_turn_deg": diff.tip_turn_deg,
            "hang_point": list(diff.hang_point), "hang_tangent": list(diff.hang_tangent),
            "arm": arm, "arm_centreline": arms[arm].points.tolist(), "radius_m": arms[arm].radius,
            "n_arms": len(arms),
            **mesh_record(solid, parts, route, iou),
            "reference_hang_position": list(hang["hang_position"]),
            "reference_hang_quat": list(hang["hang_quat"]),
            "contact_support": list(hang["contact_support"]),
            "gt_skt": skts[0]["keypoints"].tolist(),
            "skts": [s["keypoints"].tolist() for s in skts],
            "skt_min_clearance_m": [s["min_clearance_m"] for s in skts],
            "skt_path_length_m": [float(arc_length(s["keypoints"])[-1]) for s in skts],
            "n_skts_attempted": planned["n_attempted"], "skt_failures": planned["failures"],
        }
        write_json_atomic(Path(tmp) / SUPPORT_RECORD, record)
        _move_into_place(Path(tmp), user_dir(root, "support", name))
    bar.update()
    return record


def run(args) -> int:
    dest, record = run_import(args, "support", import_support)
    arm = f"arm {record['arm']} of {record['n_arms']}, " if record["n_arms"] > 1 else ""
    print(f"{dest}: imported {args.name} ({arm}{record['difficulty']}, blocking height "
          f"{1000 * record['blocking_height_m']:.1f} mm, {record['n_parts']} convex parts, IoU "
          f"{record['part_iou']:.3f}, {len(record['skts'])}/{record['n_skts_attempted']} SKTs "
          f"reach the hang); hang an object on it with `skt hang --support {args.name}`")
    return 0
