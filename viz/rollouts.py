"""Rerun recording of sim_eval rollouts, one trial at a time (support frame, like every stage).

Timelines: ``trial`` (trial n at n: its final state) and ``step`` (physics steps, trial after
trial, to replay each rollout).

    world/robot/link_<k>              Panda visual meshes (static), posed every recorded step;
                                      scaled to nothing during floating-hand trials (no arm)
                                      and at a trial's last step (its final state, what the
                                      ``trial`` timeline shows: the arm hid the hang)
    world/trials/<n>/support          the support of trial n
    world/trials/<n>/object           the object, posed every recorded step
    world/trials/<n>/skt              the SKT executed (keypoint path, the method's colour)
    world/trials/<n>/skt/frames       its waypoint frames
    world/trials/<n>/keypoint_trail   where the object's keypoint actually went
    plots/keypoint_to_skt_mm/<n>      trial n's keypoint distance from its SKT, every recorded
                                      step: a series per trial (one series across trials drew
                                      500 mm jumps from one trial's end to the next one's start)
    item/info                         trial, method, support, object, verdict
"""

from pathlib import Path

import numpy as np
import pybullet as pb
import rerun as rr
import rerun.blueprint as rrb
import trimesh

from skt_lib.geometry.se3 import pose_matrix
from skt_lib.geometry.skt import resample, skt_frames
from skt_lib.sim.robot import Panda
from skt_lib.sim.world import World
from viz.rerun_log import (
    METHOD_RGB,
    SKT_EYE,
    SKT_LOOK_AT,
    ItemTimeline,
    item_blueprint,
    log_frames,
    log_mesh,
    log_strip,
    recording,
)

_ROBOT_RGBA = (0.85, 0.85, 0.88, 1.0)
_SUPPORT_RGBA = (0.55, 0.4, 0.25, 1.0)
_OBJECT_RGBA = (0.2, 0.6, 0.9, 1.0)
_GAP = 50  # empty steps between rollouts
_TRAIL_RGB, _TRAIL_RADIUS = (250, 250, 250), 0.0008  # the keypoint trail's look
#: the arm's scale where it is hidden: the viewer ignores a zero scale (a singular transform),
#: drawing the arm at full size, so a micrometre-sized arm it is
_HIDDEN = 1e-6

#: Colours of the Table I baselines (the pipeline methods' are viz.rerun_log.METHOD_RGB).
BASELINE_RGB = {"sctdn_cp_feature": (240, 120, 160), "vatmart": (150, 90, 200),
                "vatmart_mod": (100, 40, 160), "omnihang": (40, 180, 200)}


def robot_meshes(base: tuple[float, float, float]) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """Visual meshes of the Panda per body index (0 = base, k + 1 = link k), in each link's
    frame: {index: (vertices, faces)}."""
    out: dict[int, list] = {}
    with World(1 / 240, 1, with_floor=False) as world:
        robot = Panda(world, pose_matrix(base, [0, 0, 0, 1]), visual=True)
        for shape in pb.getVisualShapeData(robot.body, physicsClientId=world.cid):
            link, geom, scale, filename = shape[1], shape[2], shape[3], shape[4]
            if geom != pb.GEOM_MESH or not filename:
                continue
            mesh = trimesh.load(filename.decode(), force="mesh", process=False)
            local = pose_matrix(shape[5], shape[6])
            v = np.asarray(mesh.vertices) * np.asarray(scale)
            v = v @ local[:3, :3].T + local[:3, 3]
            prev = out.setdefault(link + 1, [np.zeros((0, 3)), np.zeros((0, 3), int)])
            prev[1] = np.vstack([prev[1], np.asarray(mesh.faces) + len(prev[0])])
            prev[0] = np.vstack([prev[0], v])
    return {k: (v, f) for k, (v, f) in out.items()}


def _transforms(rec, entity: str, index: list, t: np.ndarray) -> None:
    """Poses ``t`` (M, 4, 4) of ``entity`` at the M times of ``index``, in one call (a rollout
    has ~2,000 of them: one ``log`` call each took two thirds of the recording's time)."""
    rec.send_columns(entity, index, rr.Transform3D.columns(translation=t[:, :3, 3],
                                                           mat3x3=t[:, :3, :3]))


def _log_trace(rec, name: str, n: int, step: int, frames: list, links, keypoint: np.ndarray,
               skt: np.ndarray) -> None:
    """Trial ``n``'s recorded steps (``frames``, from ``step`` on): robot links (``links``:
    their indices, or ``None`` for the floating hand; only in the frames that have them: the
    arm leaves after the retreat), object, keypoint trail, and the keypoint's distance from
    ``skt`` — as columns, row for row what logging each step would give."""
    index = _index(n, step, frames)
    arm = [f for f in frames if f["links"] is not None]
    for k in (links or ()) if arm else ():
        _transforms(rec, f"world/robot/link_{k}", _index(n, step, arm),
                    np.stack([World.to_support(f["links"][k]) for f in arm]))
    _transforms(rec, f"{name}/object", index, np.stack([f["object"] for f in frames]))
    trail = np.stack([(f["object"] @ keypoint)[:3, 3] for f in frames])
    rec.send_columns(f"{name}/keypoint_trail", index, rr.LineStrips3D.columns(
        strips=[trail[:i + 1] for i in range(len(trail))], colors=[_TRAIL_RGB] * len(trail),
        radii=[_TRAIL_RADIUS] * len(trail)))
    rec.send_columns(f"plots/keypoint_to_skt_mm/{n:02d}", index, rr.Scalars.columns(
        scalars=[1000 * distance_to_path(p, skt) for p in trail]))


def _index(n: int, step: int, frames: list) -> list:
    return [rr.TimeColumn("trial", sequence=[n] * len(frames)),
            rr.TimeColumn("step", sequence=[step + f["step"] for f in frames])]


def distance_to_path(point: np.ndarray, path: np.ndarray) -> float:
    """Distance from ``point`` (3,) to the polyline ``path`` (M, 3)."""
    if len(path) == 1:
        return float(np.linalg.norm(path[0] - point))
    a, ab = path[:-1], np.diff(path, axis=0)
    t = np.einsum("ij,ij->i", point - a, ab) / np.maximum(np.einsum("ij,ij->i", ab, ab), 1e-18)
    closest = a + np.clip(t, 0.0, 1.0)[:, None] * ab
    return float(np.min(np.linalg.norm(closest - point, axis=1)))


def rollouts_blueprint() -> rrb.Blueprint:
    return item_blueprint("sim_eval: one trial at a time (scrub `step` to replay it)", "trial",
                          SKT_EYE, SKT_LOOK_AT,
                          side=(rrb.TimeSeriesView(origin="plots", name="keypoint to SKT (mm)"),))


def log_rollouts(path: Path, replay: list, support_meshes: dict, object_meshes: dict,
                 base: tuple[float, float, float]) -> None:
    """``replay``: [(TrialTask, run_trial result with a trace)], recorded failures first, then
    successes (each in the given order): the viewer opens on the last trial, a success."""
    replay = sorted(replay, key=lambda tr: bool(tr[1]["row"]["success"]))
    links = robot_meshes(base)
    with recording("sim_eval", path, "sim_eval rollouts", rollouts_blueprint()) as rec:
        for k, (v, f) in links.items():
            log_mesh(rec, f"world/robot/link_{k}", v, f, _ROBOT_RGBA, static=True)
        items, step = ItemTimeline(rec, "trial"), 0
        for n, (task, result) in enumerate(replay):
            row, frames = result["row"], result["trace"]
            name = f"world/trials/{n:02d}"
            verdict = "success" if row["success"] else f"failed: {row['failure_reason']}"
            items.next(name, f"{task.trial_id}: {verdict}", times={"step": step},
                       method=task.method, support=task.support_id, object=task.object_id,
                       level=row["difficulty"], category=row["category"], grasp=row["grasp"] or "-",
                       max_track_err_mm=1000 * row["max_track_err_m"], detail=row["detail"] or "-")
            panda = bool(frames) and frames[0]["links"] is not None  # None: the floating hand
            rec.log("world/robot", rr.Transform3D(scale=1.0 if panda else _HIDDEN))
            sm, om = support_meshes[task.support_id], object_meshes[task.object_id]
            log_mesh(rec, f"{name}/support", sm.vertices, sm.faces, _SUPPORT_RGBA)
            log_mesh(rec, f"{name}/object", om.vertices, om.faces, _OBJECT_RGBA, pose=np.eye(4))
            ran = result.get("skt", 0)  # > 0: set-up fell back to that alternative SKT
            skt = np.asarray(task.alternatives[ran - 1] if ran else task.positions, np.float64)
            rgb = {**METHOD_RGB, **BASELINE_RGB}.get(task.method, (230, 60, 40))
            log_strip(rec, f"{name}/skt", skt, rgb=rgb, radius=0.0012)
            log_frames(rec, f"{name}/skt/frames", skt_frames(resample(skt, 10)), 0.008)
            if frames:
                _log_trace(rec, name, n, step, frames, links if panda else None,
                           np.asarray(task.keypoint, dtype=np.float64).reshape(4, 4), skt)
                gone = next((f for f in frames if f["links"] is None), None)
                if panda and gone is not None:  # the arm has left the scene (after the retreat)
                    rec.set_time("step", sequence=step + gone["step"])
                    rec.log("world/robot", rr.Transform3D(scale=_HIDDEN))
            step += (frames[-1]["step"] if frames else 0) + _GAP
