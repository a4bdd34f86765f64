"""The evaluation protocol (paper §V, DESIGN §5): the test set, one SKT per method and
support, one trial per (method, test support, test object), success rates per level.

The cloud each method sees is one rendered view of the support, drawn per support from the
seed (``item_rng(seed, "sim_eval", support_id)``). The ground truth of a support is its
first stored SKT (lowest ``skt_index``) resampled to ``T`` waypoints; supports without one
are left out of every method's rows and counted.
"""

import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from skt_lib.config import LEVELS, ContactSimParams, SimEvalParams
from skt_lib.eval.methods import hand_of
from skt_lib.geometry.export import read_obj
from skt_lib.geometry.se3 import pose_matrix
from skt_lib.io import read_npz, read_table
from skt_lib.perception.views import RENDER_SPEC
from skt_lib.planning.trajectory import resample
from skt_lib.schemas import KEYPOINTS, OBJECTS, SKTS, SUPPORTS
from skt_lib.seeding import item_rng
from skt_lib.sim.contact_sim import perturbation
from skt_lib.sim.execute import TrialSettings, TrialTask
from skt_lib.sim.grasp import Grasp, grasp_candidates


@dataclass(frozen=True, eq=False)
class TestSupport:
    support_id: str
    difficulty: str
    family: str
    urdf: str
    mesh: str
    gt: np.ndarray  # (T, 3) ground-truth SKT, ξ_0 first
    cloud: np.ndarray  # (N, 3) the view the methods see
    view: int


@dataclass(frozen=True, eq=False)
class TestObject:
    object_id: str
    category: str
    urdf: str
    mesh: str
    keypoint: np.ndarray  # (4, 4) keypoint frame in the object frame
    grasps: tuple[Grasp, ...]  # grasp candidates (grasp target in the keypoint frame), in order
    radius_m: float  # farthest object point from the keypoint


def load_test_set(root: Path, T: int, seed: int, grasp_pitch_deg, grasp_rolls_deg=(0.0,)
                  ) -> tuple[list[TestSupport], list[TestObject], list[str]]:
    """(test supports with a ground-truth SKT, test objects, ids of test supports without).

    Each object carries its grasp candidates (:func:`skt_lib.sim.grasp.grasp_candidates`)
    for every pitch of ``grasp_pitch_deg`` × roll of ``grasp_rolls_deg`` (degrees; pass
    ``sim_eval.grasp_pitch_deg`` and ``sim_eval.grasp_rolls_deg``), in that order."""
    pitches = (grasp_pitch_deg,) if np.isscalar(grasp_pitch_deg) else tuple(grasp_pitch_deg)
    mg = root / "mesh_gen"
    supports = read_table(mg / "supports.parquet", SUPPORTS)
    objects = read_table(mg / "objects.parquet", OBJECTS)
    skts = read_table(root / "rrt_skts" / "skts.parquet", SKTS)
    keypoints = read_table(root / "rotation_extraction" / "keypoints.parquet", KEYPOINTS)
    keypoints = keypoints.set_index("object_id")
    first = skts.sort_values(["support_id", "skt_index"]).groupby("support_id").first()
    test, missing = [], []
    for s in supports[supports["split"] == "test"].itertuples():
        if s.support_id not in first.index:
            missing.append(s.support_id)
            continue
        points = read_npz(root / "render_views" / f"{s.support_id}.npz", RENDER_SPEC)["points"]
        view = int(item_rng(seed, "sim_eval", s.support_id).integers(len(points)))
        gt = resample(np.stack(first.loc[s.support_id, "keypoints"]), T)
        test.append(TestSupport(s.support_id, s.difficulty, s.family, str(mg / s.urdf_path),
                                str(mg / s.mesh_path), gt, points[view].astype(np.float64), view))
    objs = []
    for o in objects[~objects["is_reference"] & (objects["split"] == "test")].itertuples():
        if o.object_id not in keypoints.index:
            continue  # no keypoint: rotation_extraction reports it
        kp = keypoints.loc[o.object_id]
        k = pose_matrix(kp["position"], kp["quat"])
        (mesh,) = read_obj(mg / o.mesh_path)
        objs.append(TestObject(o.object_id, o.category, str(mg / o.urdf_path), str(mg / o.mesh_path),
                               k, grasp_candidates(mesh.vertices, k, pitches, grasp_rolls_deg),
                               float(np.linalg.norm(mesh.vertices - k[:3, 3], axis=1).max())))
    return test, objs, missing


def trial_settings(p: SimEvalParams, cs: ContactSimParams) -> TrialSettings:
    """Physics (time step, solver, friction, damping, perturbation and at-rest thresholds)
    shared with ``contact_sim``; robot, grasp and execution settings from ``sim_eval``."""
    return TrialSettings(
        cs.dt, cs.solver_iterations, cs.friction, cs.linear_damping, cs.angular_damping,
        tuple(p.robot_base_m), p.step_m, p.steps_per_command, p.hold_steps, p.track_tol_m,
        p.ik_tol_m, p.ik_tol_rad, p.max_joint_step_rad, p.ik_restarts, p.setup_clearance_m,
        p.grasp_force_n, p.retreat_m, p.retreat_steps, perturbation(cs))


def predict_all(methods: dict, supports: list[TestSupport]) -> tuple[dict, dict]:
    """``methods[name](support) -> Method``; returns ({(name, support_id): positions (T, 3)},
    {name: [inference seconds per support]}), timed one support at a time (batch 1)."""
    out, seconds = {}, {name: [] for name in methods}
    for s in supports:
        for name, make in methods.items():
            method = make(s)
            t0 = time.perf_counter()
            skt = method.predict(s.cloud)
            seconds[name].append(time.perf_counter() - t0)
            out[name, s.support_id] = skt.positions
    return out, seconds


def make_task(method: str, s: TestSupport, o: TestObject, positions: np.ndarray,
              settings: TrialSettings, record_every: int = 0) -> TrialTask:
    return TrialTask(
        f"{method}/{s.support_id}/{o.object_id}", method, s.support_id, o.object_id, s.urdf, o.urdf,
        tuple(o.keypoint.ravel()), o.grasps, o.radius_m,
        tuple(map(tuple, np.asarray(positions, float))), settings, record_every,
        {"difficulty": s.difficulty, "category": o.category}, hand_of(method))


def success_table(trials: pd.DataFrame) -> dict[str, dict[str, float | None]]:
    """{method: {"all", "easy", …}} success fractions (``None`` where a level has no trials)."""
    out = {}
    for method, g in trials.groupby("method", sort=False):
        rates = {"all": float(g["success"].mean())}
        for level in LEVELS:
            sub = g[g["difficulty"] == level]
            rates[level] = float(sub["success"].mean()) if len(sub) else None
        out[method] = rates
    return out
