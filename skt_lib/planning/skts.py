"""Collect SKTs for one supporting item: plan the reference object from sampled free start
poses into its hanging pose, re-check every plan independently, convert to keypoint paths.

Start region (support frame, relative to the hanging keypoint ``k``): keypoint at
``k + (dx, dy, dz)`` with ``dx ∈ start_dx_m``, ``|dy| ≤ start_dy_m``, ``dz ∈ start_dz_m`` —
in front of the support (toward the robot) and above it — with the object turned from its
hanging orientation by a random rotation of at most ``start_rot_deg``.
"""

import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from skt_lib.config import RrtSktsParams
from skt_lib.errors import DataError
from skt_lib.geometry.export import read_obj
from skt_lib.geometry.se3 import matrix_pose, pose_matrix, random_rotation_small
from skt_lib.io import read_table
from skt_lib.parallel import run_forked
from skt_lib.planning.collision import MeshClearance, make_collision_fn
from skt_lib.planning.ompl_rrt import PlanningFailed, PlanSettings, plan, seed_ompl
from skt_lib.planning.trajectory import keypoint_positions, max_point_step
from skt_lib.schemas import CONTACTS, KEYPOINTS, OBJECTS, SUPPORTS
from skt_lib.seeding import item_rng
from skt_lib.sim.world import World

BOUNDS_MARGIN_M = 0.08


@dataclass(frozen=True)
class SktTask:
    support_id: str
    support_urdf: str
    support_mesh: str
    object_urdf: str
    object_mesh: str
    keypoint: tuple[float, float, float]  # reference keypoint, object frame
    goal_position: tuple[float, float, float]  # hanging pose, support frame
    goal_quat: tuple[float, float, float, float]  # xyzw
    seed: int
    params: RrtSktsParams


def load_skt_tasks(root: Path, seed: int, p: RrtSktsParams) -> list[SktTask]:
    """One task per support with a hanging pose, from the artifacts under ``root`` (the
    ``data/`` folder): mesh_gen, contact_sim and rotation_extraction outputs."""
    mg = root / "mesh_gen"
    supports = read_table(mg / "supports.parquet", SUPPORTS).set_index("support_id")
    objects = read_table(mg / "objects.parquet", OBJECTS)
    contacts = read_table(root / "contact_sim" / "contacts.parquet", CONTACTS)
    keypoints = read_table(root / "rotation_extraction" / "keypoints.parquet", KEYPOINTS)
    ref, ref_kp = objects[objects["is_reference"]].iloc[0], keypoints[keypoints["is_reference"]]
    if ref_kp.empty:
        raise DataError(f"{root / 'rotation_extraction' / 'keypoints.parquet'}: the reference "
                        "object has no keypoint")
    kp = tuple(ref_kp.iloc[0]["position"])
    hangs = contacts[(contacts["kind"] == "reference_on_support") & contacts["ok"]]
    return [SktTask(h.support_id, str(mg / supports.loc[h.support_id, "urdf_path"]),
                    str(mg / supports.loc[h.support_id, "mesh_path"]), str(mg / ref.urdf_path),
                    str(mg / ref.mesh_path), kp, tuple(h.hang_position), tuple(h.hang_quat), seed, p)
            for h in hangs.itertuples()]


def settings(p: RrtSktsParams, object_radius: float) -> PlanSettings:
    return PlanSettings(p.range_m, p.check_step_m, p.max_checks, p.simplify_steps,
                        p.dense_step_m, object_radius)


def sample_start(rng, goal: np.ndarray, keypoint: np.ndarray, p: RrtSktsParams) -> np.ndarray:
    """A start pose in the documented region (may collide; the caller checks)."""
    k_goal = goal[:3, :3] @ keypoint + goal[:3, 3]
    k = k_goal + np.array([rng.uniform(*p.start_dx_m), rng.uniform(-p.start_dy_m, p.start_dy_m),
                           rng.uniform(*p.start_dz_m)])
    rot = random_rotation_small(rng, p.start_rot_deg) @ goal[:3, :3]
    t = np.eye(4)
    t[:3, :3], t[:3, 3] = rot, k - rot @ keypoint
    return t


def plan_support_skts(task: SktTask) -> dict:
    """All SKTs of one support, planned in a forked child (fresh, seeded OMPL)."""
    return run_forked(_plan_in_child, task)


def _plan_in_child(task: SktTask) -> dict:
    p = task.params
    rng = item_rng(task.seed, "rrt_skts", task.support_id)
    seed_ompl(int(rng.integers(1, 2**31 - 1)))
    goal = pose_matrix(task.goal_position, task.goal_quat)
    keypoint = np.asarray(task.keypoint, dtype=np.float64)
    (support_mesh,) = read_obj(task.support_mesh)
    (object_mesh,) = read_obj(task.object_mesh)
    radius = float(np.linalg.norm(object_mesh.vertices, axis=1).max())
    checker = MeshClearance(support_mesh, object_mesh, p.recheck_spacing_m)
    k_goal = goal[:3, :3] @ keypoint + goal[:3, 3]
    corners = np.vstack([support_mesh.vertices, k_goal + [p.start_dx_m[1], p.start_dy_m, p.start_dz_m[1]],
                         k_goal + [0.0, -p.start_dy_m, 0.0]])
    lower = corners.min(0) - BOUNDS_MARGIN_M
    upper = corners.max(0) + BOUNDS_MARGIN_M
    lower[0] = max(lower[0], 0.0)

    skts, failures, plan_s, recheck_s = [], Counter(), [], []
    n_planned = n_recheck_ok = 0
    with World(dt=1 / 240, solver_iterations=1, with_floor=False) as world:
        wall = world.add_wall()
        sup = world.load(task.support_urdf, np.eye(4), fixed=True, friction=0.5)
        obj = world.load(task.object_urdf, goal, fixed=False, friction=0.5)
        collides_pq = make_collision_fn(world, obj, [sup, wall], p.planner_clearance_m)

        def collides(t: np.ndarray) -> bool:
            position, quat = matrix_pose(t)
            return collides_pq(position, quat)
        for index in range(p.n_skts_per_support):
            for _ in range(p.max_start_tries):
                start = sample_start(rng, goal, keypoint, p)
                if np.all(start[:3, 3] > lower) and np.all(start[:3, 3] < upper) and not collides(start):
                    break
            else:
                failures["no_free_start"] += 1
                continue
            t0 = time.perf_counter()
            try:
                poses, n_checks = plan(start, goal, collides_pq, lower, upper, settings(p, radius))
            except PlanningFailed as err:
                plan_s.append(time.perf_counter() - t0)
                failures[err.reason] += 1
                continue
            plan_s.append(time.perf_counter() - t0)
            n_planned += 1
            t1 = time.perf_counter()
            clearance = checker.clearance(poses)
            step = max_point_step(poses, object_mesh.vertices)
            recheck_s.append(time.perf_counter() - t1)
            if clearance <= 0.0 or step > p.recheck_step_m:
                failures["recheck_collision" if clearance <= 0 else "recheck_coarse"] += 1
                continue
            n_recheck_ok += 1
            order = poses[::-1]  # ξ_0 (hang) first
            skts.append({"index": index, "poses": order, "n_checks": n_checks,
                         "keypoints": keypoint_positions(order, keypoint),
                         "min_clearance_m": clearance, "max_step_m": step})
    return {"support_id": task.support_id, "skts": skts, "failures": dict(failures),
            "plan_s": plan_s, "recheck_s": recheck_s, "n_planned": n_planned,
            "n_recheck_ok": n_recheck_ok, "n_attempted": p.n_skts_per_support}
