"""The evaluation protocol (paper §V, docs/design.md §5): the test set, one SKT per method and
support, one trial per (method, test support, test object), success rates per level.

The cloud each method sees is one rendered view of the support, drawn per support from the
seed (``item_rng(seed, "sim_eval", support_id)``). The ground truth of a support is its
first stored SKT (lowest ``skt_index``) resampled to ``T`` waypoints; supports without one
are left out of every method's rows and counted. The oracles' set-up chooses among all the
support's stored SKTs (:data:`~skt_lib.eval.methods.FALLS_BACK_TO_STORED`).
"""

import time
from pathlib import Path

import numpy as np
import pandas as pd

from skt_lib.config import LEVELS
from skt_lib.config.contact_sim import ContactSimParams
from skt_lib.config.sim_eval import SimEvalParams
from skt_lib.errors import DataError
from skt_lib.eval.methods import FALLS_BACK_TO_STORED, hand_of
from skt_lib.geometry.export import read_obj
from skt_lib.geometry.se3 import pose_matrix
from skt_lib.geometry.skt import resample
from skt_lib.io import read_npz, read_table
from skt_lib.items import TestObject, TestSupport
from skt_lib.perception.views import RENDER_SPEC
from skt_lib.schemas import KEYPOINTS, OBJECTS, SKTS, SUPPORTS
from skt_lib.seeding import item_rng
from skt_lib.sim.contact_sim import perturbation
from skt_lib.sim.execute import TrialSettings, TrialTask
from skt_lib.sim.grasp import grasp_candidates


def load_test_set(root: Path, T: int, seed: int, grasp_pitch_deg, grasp_rolls_deg=(0.0,),
                  grasp_yaws_deg=(0.0,), support_split: str = "test", object_split: str = "test",
                  grasp_sphere: int = 0) -> tuple[list[TestSupport], list[TestObject], list[str]]:
    """(test supports with a ground-truth SKT, test objects, ids of test supports without).

    Each object carries its grasp candidates (:func:`skt_lib.sim.grasp.grasp_candidates`)
    for every yaw of ``grasp_yaws_deg`` × pitch of ``grasp_pitch_deg`` × roll of
    ``grasp_rolls_deg`` (degrees; pass ``sim_eval``'s), in that order, then ``grasp_sphere``
    directions × the rolls (``sim_eval.grasp_sphere_directions``). ``support_split`` /
    ``object_split``: the splits to take them from (Table I: both ``test``; validation in
    simulation, :mod:`tools.val_sim`: ``val`` supports with ``train`` objects)."""
    pitches = (grasp_pitch_deg,) if np.isscalar(grasp_pitch_deg) else tuple(grasp_pitch_deg)
    mg = root / "mesh_gen"
    supports = read_table(mg / "supports.parquet", SUPPORTS)
    objects = read_table(mg / "objects.parquet", OBJECTS)
    skts = read_table(root / "rrt_skts" / "skts.parquet", SKTS)
    keypoints = read_table(root / "rotation_extraction" / "keypoints.parquet", KEYPOINTS)
    keypoints = keypoints.set_index("object_id")
    stored = {sid: [resample(np.stack(k), T) for k in g["keypoints"]]
              for sid, g in skts.sort_values(["support_id", "skt_index"]).groupby("support_id")}
    test, missing = [], []
    for s in supports[supports["split"] == support_split].itertuples():
        if s.support_id not in stored:
            missing.append(s.support_id)
            continue
        points = read_npz(root / "render_views" / f"{s.support_id}.npz", RENDER_SPEC)["points"]
        view = int(item_rng(seed, "sim_eval", s.support_id).integers(len(points)))
        gt, *others = stored[s.support_id]
        test.append(TestSupport(s.support_id, s.difficulty, s.family, str(mg / s.urdf_path),
                                str(mg / s.mesh_path), gt, points[view].astype(np.float64), view,
                                tuple(others)))
    objs = []
    for o in objects[~objects["is_reference"] & (objects["split"] == object_split)].itertuples():
        if o.object_id not in keypoints.index:
            continue  # no keypoint: rotation_extraction reports it
        kp = keypoints.loc[o.object_id]
        k = pose_matrix(kp["position"], kp["quat"])
        (mesh,) = read_obj(mg / o.mesh_path)
        objs.append(TestObject(o.object_id, o.category, str(mg / o.urdf_path), str(mg / o.mesh_path),
                               k, grasp_candidates(mesh.vertices, k, pitches, grasp_rolls_deg,
                                                                 yaws_deg=grasp_yaws_deg,
                                                                 sphere=grasp_sphere),
                               float(np.linalg.norm(mesh.vertices - k[:3, 3], axis=1).max())))
    return test, objs, missing


def reference_points(root: Path, spacing: float = 0.004) -> np.ndarray:
    """Surface samples ``(K, 3)`` of the reference object in its keypoint frame: the object
    ``omnihang`` plans for (the SKT methods' one path per support serves every object; the
    reference object is the one the ground-truth SKTs were threaded with)."""
    from skt_lib.geometry.se3 import invert, transform_points
    from skt_lib.planning.collision import surface_samples

    mg = root / "mesh_gen"
    objects = read_table(mg / "objects.parquet", OBJECTS)
    ref = objects[objects["is_reference"]]
    if len(ref) != 1:
        raise DataError(f"{mg / 'objects.parquet'}: expected one reference object, found {len(ref)}")
    kps = read_table(root / "rotation_extraction" / "keypoints.parquet", KEYPOINTS).set_index("object_id")
    oid = ref["object_id"].iloc[0]
    if oid not in kps.index:
        raise DataError(f"{root / 'rotation_extraction'}: no keypoint for the reference {oid}")
    (mesh,) = read_obj(mg / ref["mesh_path"].iloc[0])
    k = pose_matrix(kps.loc[oid, "position"], kps.loc[oid, "quat"])
    return transform_points(invert(k), surface_samples(mesh, spacing))


def trial_settings(p: SimEvalParams, cs: ContactSimParams) -> TrialSettings:
    """Physics (time step, solver, friction, perturbation and at-rest thresholds) shared with
    ``contact_sim``; the object's damping, robot, grasp and execution settings from
    ``sim_eval``."""
    return TrialSettings(
        cs.dt, cs.solver_iterations, cs.friction, p.linear_damping, p.angular_damping,
        p.settle_linear_damping, p.settle_angular_damping, tuple(p.robot_base_m), p.step_m, p.steps_per_command, p.hold_steps, p.track_tol_m,
        p.ik_tol_m, p.ik_tol_rad, p.max_joint_step_rad, p.ik_restarts, p.setup_clearance_m,
        p.grasp_force_n, p.retreat_m, p.retreat_steps, perturbation(cs))


def predict_all(methods: dict, supports: list[TestSupport]) -> tuple[dict, dict, dict, dict]:
    """``methods[name](support) -> Method``; returns ({(name, support_id): [positions (T, 3),
    …]}, {name: [inference seconds per support]}, {(name, support_id): method},
    {(name, support_id): (fallback positions (T, 3), …)}), timed one support at a time
    (batch 1). A proposing method (one with ``propose``) gives all its proposals, timed
    together, and no fallbacks; any other method one SKT and its ``fallbacks`` (the cloud
    check's other candidates, clearest first; empty for most methods)."""
    out, seconds, made, fallbacks = {}, {name: [] for name in methods}, {}, {}
    for s in supports:
        for name, make in methods.items():
            method = make(s)
            t0 = time.perf_counter()
            skts = method.propose(s.cloud) if hasattr(method, "propose") else [method.predict(s.cloud)]
            seconds[name].append(time.perf_counter() - t0)
            out[name, s.support_id] = [skt.positions for skt in skts]
            made[name, s.support_id] = method
            fallbacks[name, s.support_id] = () if len(skts) > 1 else skts[0].fallbacks
    return out, seconds, made, fallbacks


def make_task(method: str, s: TestSupport, o: TestObject, positions: np.ndarray,
              settings: TrialSettings, record_every: int = 0, proposal: int = 0,
              fallbacks=()) -> TrialTask:
    """One trial; ``proposal`` > 0 for a proposing method's later proposals (their ids end in
    ``/p<proposal>``). The set-up's alternatives: the support's other stored SKTs, swept
    through the support first, for :data:`FALLS_BACK_TO_STORED`; else ``fallbacks`` (a
    checked learned method's other candidates, ``(T, 3)`` each), in their order, unswept."""
    tid = f"{method}/{s.support_id}/{o.object_id}" + (f"/p{proposal}" if proposal else "")
    stored = method in FALLS_BACK_TO_STORED
    others = s.others if stored else fallbacks
    # plain Python floats, not numpy scalars: the same values, a tenth of the pickle
    return TrialTask(
        tid, method, s.support_id, o.object_id, s.urdf, o.urdf,
        tuple(np.asarray(o.keypoint, float).ravel().tolist()), o.grasps, float(o.radius_m),
        tuple(map(tuple, np.asarray(positions, float).tolist())), settings, record_every,
        {"difficulty": s.difficulty, "category": o.category, "proposal": proposal}, hand_of(method),
        tuple(tuple(map(tuple, np.asarray(k, float).tolist())) for k in others), stored)


#: Suffix of the single-sample rows :func:`per_pair` adds for proposing methods.
SINGLE = "@1"


def per_pair(trials: pd.DataFrame) -> pd.DataFrame:
    """One row per (method, support, object). A pair with several proposals (rows with
    ``proposal`` > 0) succeeds if any proposal hung the object (the paper's best-of-N) and
    keeps proposal 0's failure reason when none did; it also gets a row ``<method>@1`` with
    proposal 0 alone (the honest single-sample rate). Row order: the table's, per method."""
    first = trials[trials["proposal"] == 0]
    multi = set(trials.loc[trials["proposal"] > 0, "method"])
    if not multi:
        return first.reset_index(drop=True)
    key = ["method", "support_id", "object_id"]
    anyok = trials.groupby(key, sort=False)["success"].any()
    parts = []
    for method, g in first.groupby("method", sort=False):
        if method in multi:
            best = g.copy()
            best["success"] = anyok.loc[[tuple(r) for r in g[key].to_numpy()]].to_numpy()
            best.loc[best["success"], "failure_reason"] = ""
            single = g.copy()
            single["method"] = method + SINGLE
            parts += [best, single]
        else:
            parts.append(g)
    return pd.concat(parts, ignore_index=True)


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
