"""Room along a curl (after ``make repro``): why the threading planner finds no SKT on a
tight curl — the mesh zoo's pigtail, support_00155 of the default data.

The reference object is carried along the hanging arm's threading route
(:func:`skt_lib.planning.route.arm_route`: from the hang back along the arm, round or over
its tip and on past it) at the frames an SKT along that route has (rotation-minimizing, the
roll carried from the hang: :func:`skt_lib.geometry.skt.skt_frames`), and measured pose by
pose by the exact mesh check with the wall (:class:`~skt_lib.planning.collision.MeshClearance`):

- ``clearance_mm``: on the route (the rod at the keypoint's place in the ring);
- ``wall_mm``: the object's least x there (< 0: through the wall);
- ``room_mm``: the best clearance with the keypoint moved up to :data:`OFFSET_M` across the
  route (in the frame's y–z plane; a 9 × 9 grid, then :data:`REFINE` finer grids round the
  best) — what a centred path, each pose's position searched for the most room, could give
  at those frames;
- ``roll_deg``: where that room falls short of the planner's ``clearance_m``, the least roll
  about the direction of motion (steps of :data:`ROLL_STEP_DEG`, the keypoint moved as
  above) that gives it room (``null``: none up to 180°). An SKT's frames give no roll of
  their own: only a path whose direction sweeps a solid angle turns the object so.

The frames are the route's: moving the keypoint across the route would also turn them a
little, so ``room_mm`` is a measurement at the route's frames, not a plan.

And at the hang, where every SKT ends (:mod:`skt_lib.planning.release`): each candidate
straight lead-in into the release the planner tries (lifts and set-backs ≤
``max_release_offset_m``, arrival directions turned from the hanging keypoint's x), by the
exact check and by the planner's own probe (PyBullet, the support's convex parts, the
reference at ``clearance_m``): ``release_exact_clear`` and ``release_probe_clear`` of
``release_candidates``. A support none of whose lead-ins the probe clears fails as
``lead_in_blocked`` before any tree grows.

    .venv/bin/python -m tools.route_room                      # the pigtail and support_00155
    .venv/bin/python -m tools.route_room --case pigtail --support support_00001

A zoo case is imported as ``skt import-support`` imports it (its hang dropped as
``contact_sim`` drops it) up to the planning, which is measured here instead; a pipeline
support takes ``rrt_skts``' task. Writes ``route_room.json``, ``route_room.md`` and
``route_room.png`` into ``--out-dir`` (default ``reports/rrt_skts``); nothing under the data
root changes.
"""

import argparse
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from skt_lib.cli.import_support import import_support
from skt_lib.cli.mesh_zoo import cases
from skt_lib.config.params_file import load_params
from skt_lib.errors import DataError
from skt_lib.geometry.convex import Mesh
from skt_lib.geometry.export import read_obj
from skt_lib.geometry.se3 import invert, pose_matrix
from skt_lib.geometry.skt import arc_length, skt_frames
from skt_lib.io import write_json_atomic
from skt_lib.planning.collision import MeshClearance
from skt_lib.planning.frames import frame, rotation_quat, unit
from skt_lib.planning.probe import ProbeObject, add_probe, make_probe_collision_fn
from skt_lib.planning.release import arrival_directions, release_offsets
from skt_lib.planning.route import arm_route
from skt_lib.planning.skts import ROUTE_BEYOND_M, SktTask, load_skt_tasks
from skt_lib.geometry.se3 import skt_rotation
from skt_lib.sim.world import World

#: The route is measured every this many of its points (one a millimetre).
EVERY = 2
#: How far (m) the keypoint is moved across the route, each way: a 9 × 9 grid (3 mm apart),
#: then :data:`REFINE` 5 × 5 grids round each pose's best offset, each half as far apart.
OFFSET_M = 0.012
REFINE = 2
#: Rolls tried about the direction of motion where the route's own frames leave no room.
ROLL_STEP_DEG = 15
#: Sample spacing (m) of the meshes for the clearance (``rrt_skts.recheck_spacing_m``).
SPACING_M = 0.002


@dataclass(frozen=True)
class RouteRoom:
    """The reference object along a threading route, pose by pose (``(K,)`` arrays, from
    the hang outward; metres and degrees; module notes)."""

    along_m: np.ndarray
    clearance_m: np.ndarray
    wall_m: np.ndarray
    room_m: np.ndarray
    roll_deg: np.ndarray  # 0 where room_m suffices, nan where no roll up to 180° does
    need_m: float

    @property
    def blocked(self) -> np.ndarray:
        """Poses without ``need_m`` of room at the route's frames, wherever the keypoint sits."""
        return self.room_m < self.need_m

    def as_json(self) -> dict:
        mm = {k: np.round(1000 * getattr(self, k), 2).tolist()
              for k in ("along_m", "clearance_m", "wall_m", "room_m")}
        k = int(np.argmin(self.clearance_m))
        return {"need_mm": 1000 * self.need_m, "n_poses": len(self.along_m),
                "n_blocked": int(self.blocked.sum()),
                "least_clearance_mm": 1000 * float(self.clearance_m[k]),
                "least_clearance_at_mm": 1000 * float(self.along_m[k]),
                "least_clearance_is_wall": bool(self.wall_m[k] <= self.clearance_m[k] + 1e-4),
                "least_room_mm": 1000 * float(self.room_m.min()),
                **{key.replace("_m", "_mm"): v for key, v in mm.items()},
                "roll_deg": [None if np.isnan(r) else float(r) for r in self.roll_deg]}


def _rolled(frames: np.ndarray, roll_deg: float, offsets: np.ndarray) -> np.ndarray:
    """Each of ``frames (K, 4, 4)`` rolled about its x by ``roll_deg``, then moved by its
    own ``offsets (K, M, 2)`` along its (rolled) y and z: ``(K, M, 4, 4)``."""
    c, s = np.cos(np.radians(roll_deg)), np.sin(np.radians(roll_deg))
    roll = np.array([[1.0, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1]])
    out = np.repeat((frames @ roll)[:, None], offsets.shape[1], axis=1)
    out[..., :3, 3] += out[..., :3, 1] * offsets[..., :1] + out[..., :3, 2] * offsets[..., 1:]
    return out


def _grid(n: int) -> np.ndarray:
    return np.stack(np.meshgrid(*[np.linspace(-1.0, 1.0, n)] * 2, indexing="ij"), -1).reshape(-1, 2)


def route_room(support: Mesh, reference: Mesh, keypoint: np.ndarray, hang: np.ndarray,
               need_m: float, beyond_m: float = ROUTE_BEYOND_M) -> RouteRoom:
    """The reference object (``reference``, object frame; ``keypoint (4, 4)`` its keypoint
    frame there) along the threading route of ``support`` from the hanging keypoint position
    ``hang (3,)`` (support frame); ``need_m``: the room asked for (module notes)."""
    route = arm_route(support, np.asarray(hang, float), beyond_m)
    frames = skt_frames(route)[::EVERY]
    along = arc_length(route)[::EVERY]
    check = MeshClearance(support, reference, SPACING_M)
    to_object = invert(np.asarray(keypoint, float))

    def best(at: np.ndarray, roll: float) -> np.ndarray:
        """(K,) the most room of each of ``at`` rolled by ``roll``, the keypoint moved."""
        centre, spread, unit = np.zeros((len(at), 2)), OFFSET_M, _grid(9)
        for _ in range(REFINE + 1):
            offsets = np.clip(centre[:, None] + spread * unit[None], -OFFSET_M, OFFSET_M)
            v = check.per_pose((_rolled(at, roll, offsets) @ to_object).reshape(-1, 4, 4))
            v = v.reshape(len(at), -1)
            centre, value = offsets[np.arange(len(at)), v.argmax(axis=1)], v.max(axis=1)
            # the next grid spans the best point's neighbours, half as far apart
            spread, unit = 2 * spread / (np.sqrt(len(unit)) - 1), _grid(5)
        return value

    vertices = np.c_[reference.vertices, np.ones(len(reference.vertices))]
    wall = np.array([(vertices @ (f @ to_object).T)[:, 0].min() for f in frames])
    room = best(frames, 0.0)
    roll = np.where(room >= need_m, 0.0, np.nan)
    todo = np.flatnonzero(room < need_m)
    for step in range(ROLL_STEP_DEG, 181, ROLL_STEP_DEG):  # the least |roll| first
        if not len(todo):
            break
        got = np.maximum(best(frames[todo], step), best(frames[todo], -step))
        roll[todo[got >= need_m]] = step
        todo = todo[got < need_m]
    return RouteRoom(along, check.per_pose(frames @ to_object), wall, room, roll, need_m)


def release_room(task: SktTask, check: MeshClearance) -> dict:
    """The planner's candidate lead-ins into the release of ``task`` (module notes): how
    many clear ``clearance_m`` by the exact check and by the planner's probe, of how many,
    and the most exact clearance among them (mm)."""
    p = task.params
    keypoint = np.asarray(task.reference.keypoint, float).reshape(4, 4)
    goal = pose_matrix(task.goal_position, task.goal_quat) @ keypoint
    hang, a0 = goal[:3, 3], unit(goal[:3, 0])
    lifts, rest = release_offsets(p.max_release_offset_m)
    exact, probe, best = 0, 0, -np.inf
    with World(dt=1 / 240, solver_iterations=1, with_floor=False) as world:
        obstacles = [world.load(task.support_urdf, np.eye(4), fixed=True, friction=0.5),
                     world.add_wall()]
        body = add_probe(world, [ProbeObject(task.reference.collision, task.reference.keypoint)])
        collides = make_probe_collision_fn(world, body, obstacles, p.clearance_m,
                                           p.penetration_tol_m)
        candidates = 0
        for d in arrival_directions(a0):
            try:
                r0 = skt_rotation(d)
            except ValueError:  # vertical: the planner skips it too
                continue
            q = rotation_quat(r0)
            for lift, back in lifts + rest:
                p0 = hang + [0.0, 0.0, lift] - back * d
                if p0[2] < hang[2] - 1e-12:
                    continue
                lead = p0 - np.outer(np.linspace(0.0, p.lead_in_m, 4), d)
                poses = np.stack([frame(x, r0) for x in lead]) @ invert(keypoint)
                value = check.per_pose(poses).min()
                candidates += 1
                exact += int(value >= p.clearance_m)
                probe += int(not any(collides(x, q) for x in lead))
                best = max(best, float(value))
    return {"release_candidates": candidates, "release_exact_clear": exact,
            "release_probe_clear": probe, "release_best_exact_mm": 1000 * best}


def measure_task(task: SktTask) -> tuple[RouteRoom, dict]:
    """:func:`route_room` and :func:`release_room` of the reference object of an
    ``rrt_skts`` task at its hang."""
    keypoint = np.asarray(task.reference.keypoint, float).reshape(4, 4)
    hang = (pose_matrix(task.goal_position, task.goal_quat) @ keypoint)[:3, 3]
    (support,) = read_obj(task.support_mesh)
    reference = read_obj(task.reference.mesh)[0]
    return (route_room(support, reference, keypoint, hang, task.params.clearance_m),
            release_room(task, MeshClearance(support, reference, SPACING_M)))


class _Measured(Exception):
    """Carries a zoo case's measurement out of ``import_support`` (whose temporary folder,
    the case's meshes, is gone once it returns)."""


def zoo_task_room(name: str, root: Path, params_path: Path, work: Path) -> tuple[RouteRoom, dict]:
    """:func:`measure_task` of the mesh zoo case ``name`` on the first arm where the
    reference object hangs, imported as ``skt import-support`` imports it into a data root
    of its own (``work``; the stages it reads from ``root`` linked), up to the planning."""
    from skt_lib.cli.mesh_zoo import linked_root

    case = next((c for c in cases() if c.name == name and c.kind == "support"), None)
    if case is None:
        raise DataError(f"--case {name}: no support case of that name in the mesh zoo")
    mesh = case.write(work)
    args = SimpleNamespace(mesh=str(mesh), name=name, units="m", mount=None, out_axis=None,
                           arm=None, data_root=str(linked_root(work, "root", root)))

    def measure(task: SktTask):
        raise _Measured(measure_task(task))

    try:
        import_support(args, load_params(params_path), SimpleNamespace(update=lambda: None),
                       plan=measure)
    except _Measured as got:
        return got.args[0]
    raise DataError(f"--case {name}: the reference object hangs on no arm of it")


def _span(values: np.ndarray) -> str:
    lo, hi = f"{values.min():.0f}", f"{values.max():.0f}"
    return lo if lo == hi else f"{lo}–{hi}"


def write_reports(rooms: dict[str, tuple[RouteRoom, dict]], out: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(out / "route_room.json",
                      {k: r.as_json() | rel for k, (r, rel) in rooms.items()})
    fig, axes = plt.subplots(1, len(rooms), figsize=(6 * len(rooms), 3.6), squeeze=False)
    need = next(iter(rooms.values()))[0].need_m
    lines = ["# Room along a curl (`python -m tools.route_room`)", "",
             "The reference object carried along each support's threading route at the frames "
             "an SKT along it has, measured by the exact mesh check with the wall "
             "(`tools/route_room.py` says how). Lengths along the route from the hang.", "",
             "| support | poses | least clearance on the route (mm, at mm) | meets | poses "
             f"without {1000 * need:.1f} mm of room, the keypoint "
             f"within {1000 * OFFSET_M:.0f} mm of the route | their least room (mm) | a roll "
             "gives room at | lead-ins clear: exact / probe / tried |",
             "|---|---|---|---|---|---|---|---|"]
    for ax, (name, (r, rel)) in zip(axes[0], rooms.items()):
        j = r.as_json()
        blocked = r.blocked
        rolls = r.roll_deg[blocked]
        found = rolls[~np.isnan(rolls)]
        lines.append(f"| {name} | {j['n_poses']} | {j['least_clearance_mm']:.1f} at "
                     f"{j['least_clearance_at_mm']:.0f} | "
                     f"{'the wall' if j['least_clearance_is_wall'] else 'the support'} | "
                     f"{j['n_blocked']} | {j['least_room_mm']:.1f} | "
                     + (f"{len(found)} of them ({_span(found)}°)" if len(found) else "none")
                     + f" | {rel['release_exact_clear']} / {rel['release_probe_clear']} / "
                     f"{rel['release_candidates']} |")
        along = 1000 * r.along_m
        ax.plot(along, 1000 * r.clearance_m, label="on the route")
        ax.plot(along, 1000 * r.wall_m, ":", label="wall (least x)")
        ax.plot(along, 1000 * r.room_m, label=f"keypoint moved ≤ {1000 * OFFSET_M:.0f} mm")
        ax.axhline(1000 * r.need_m, color="k", lw=0.6, ls="--")
        ax.set_ylim(-20, 8)
        ax.set(title=name, xlabel="along the route from the hang (mm)", ylabel="clearance (mm)")
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(out / "route_room.png", dpi=110)
    plt.close(fig)
    (out / "route_room.md").write_text("\n".join([*lines, "", "![](route_room.png)", ""]))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="tools/route_room.py", description=__doc__.splitlines()[0])
    ap.add_argument("--params", default="params.yaml", type=Path)
    ap.add_argument("--data-root", default="data", type=Path)
    ap.add_argument("--case", nargs="*", default=["pigtail"], help="mesh zoo support cases")
    ap.add_argument("--support", nargs="*", default=["support_00155"], help="pipeline supports")
    ap.add_argument("--out-dir", default="reports/rrt_skts", type=Path)
    args = ap.parse_args(argv)
    params = load_params(args.params)
    rooms = {}
    with tempfile.TemporaryDirectory(prefix="route-room-") as tmp:
        for name in args.case:
            (Path(tmp) / name).mkdir()
            rooms[name] = zoo_task_room(name, args.data_root, args.params, Path(tmp) / name)
    if args.support:
        tasks = {t.support_id: t for t in load_skt_tasks(args.data_root, params.common.seed,
                                                          params.rrt_skts, params.clustering.T)}
        for sid in args.support:
            if sid not in tasks:
                raise DataError(f"--support {sid}: no hanging pose for it under {args.data_root}")
            rooms[sid] = measure_task(tasks[sid])
    write_reports(rooms, args.out_dir)
    for name, (r, rel) in rooms.items():
        j = r.as_json()
        print(f"{name}: {j['n_blocked']} of {j['n_poses']} poses without room; least "
              f"clearance {j['least_clearance_mm']:.1f} mm at {j['least_clearance_at_mm']:.0f} mm; "
              f"lead-ins clear {rel['release_exact_clear']} exact, {rel['release_probe_clear']} "
              f"probe, of {rel['release_candidates']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
