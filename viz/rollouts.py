"""Rerun recording of sim_eval rollouts: Panda links, the held object, the support and the
SKT, one rollout after another on the ``step`` timeline (support frame, like every stage).

    world/robot/link_<k>            Panda visual meshes, posed every recorded step
    world/rollouts/<n>/support      the support of rollout n (shown during it only)
    world/rollouts/<n>/object       the object, posed every recorded step
    world/rollouts/<n>/skt          the SKT executed (keypoint path)
"""

from pathlib import Path

import numpy as np
import pybullet as pb
import rerun as rr
import trimesh

from skt_lib.geometry.se3 import pose_matrix
from skt_lib.sim.robot import Panda
from skt_lib.sim.world import World
from viz.rerun_log import recording

_ROBOT_RGBA = (0.85, 0.85, 0.88, 1.0)
_GAP = 50  # empty steps between rollouts


def robot_meshes(base: tuple[float, float, float]) -> dict[int, tuple[np.ndarray, np.ndarray]]:
    """Visual meshes of the Panda per body index (0 = base, k + 1 = link k), in each link's
    frame: {index: (vertices, faces)}."""
    out: dict[int, list] = {}
    with World(1 / 240, 1, with_floor=False) as world:
        robot = Panda(world, pose_matrix(base, [0, 0, 0, 1]))
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


def _transform(rec, entity: str, t: np.ndarray) -> None:
    rec.log(entity, rr.Transform3D(translation=t[:3, 3], mat3x3=t[:3, :3]))


def log_rollouts(path: Path, replay: list, support_meshes: dict, object_meshes: dict,
                 base: tuple[float, float, float]) -> None:
    """``replay``: [(TrialTask, run_trial result with a trace)]."""
    links = robot_meshes(base)
    with recording("sim_eval", path, "sim_eval rollouts") as rec:
        for k, (v, f) in links.items():
            rec.log(f"world/robot/link_{k}/mesh",
                    rr.Mesh3D(vertex_positions=v.astype(np.float32), triangle_indices=f.astype(np.uint32),
                              albedo_factor=list(_ROBOT_RGBA)), static=True)
        step = 0
        for n, (task, result) in enumerate(replay):
            row, frames = result["row"], result["trace"]
            name = f"world/rollouts/{n:02d}_{task.method}_{row['failure_reason'] or 'success'}"
            rec.set_time("step", sequence=step)
            sm, om = support_meshes[task.support_id], object_meshes[task.object_id]
            rec.log(f"{name}/support", rr.Mesh3D(vertex_positions=sm.vertices.astype(np.float32),
                                                 triangle_indices=sm.faces.astype(np.uint32),
                                                 albedo_factor=[0.55, 0.4, 0.25, 1.0]))
            rec.log(f"{name}/object/mesh", rr.Mesh3D(vertex_positions=om.vertices.astype(np.float32),
                                                     triangle_indices=om.faces.astype(np.uint32),
                                                     albedo_factor=[0.2, 0.6, 0.9, 1.0]))
            rec.log(f"{name}/skt", rr.LineStrips3D([np.asarray(task.positions)], colors=[(230, 60, 40)],
                                                   radii=0.001))
            rec.log(name, rr.TextDocument(f"{task.trial_id}: {row['failure_reason'] or 'success'} "
                                          f"({row['difficulty']}, {row['category']})"))
            for frame in frames:
                rec.set_time("step", sequence=step + frame["step"])
                if frame["links"] is not None:  # None: the floating hand (no robot)
                    for k in links:
                        _transform(rec, f"world/robot/link_{k}", World.to_support(frame["links"][k]))
                _transform(rec, f"{name}/object", frame["object"])
            step += (frames[-1]["step"] if frames else 0) + _GAP
            rec.set_time("step", sequence=step - 1)
            rec.log(name, rr.Clear(recursive=True))
