"""Collect SKTs for one supporting item: thread the probe (reference + training objects)
from free start positions into the hanging pose (:mod:`skt_lib.planning.threading`), re-check
every SKT independently *as executed*, and measure how test objects fare along it.

Start region (support frame, relative to the hanging keypoint ``k``): keypoint at
``k + (dx, dy, dz)`` with ``dx ∈ start_dx_m``, ``|dy| ≤ start_dy_m``, ``dz ∈ start_dz_m`` —
in front of the support (toward the robot) and above it; the path is extended to the
region's centre (the canonical start) where it can be, so that a support's SKTs are
comparable as whole paths and their family is decided by the support, not by a random start.
The orientation along the path is the SKT frames' (it follows the motion, its roll carried
from the hanging orientation), so no start orientation is drawn. Every SKT ends at the hang
(ξ_0 at most ``max_release_offset_m`` above it): :data:`REACH_TOL_M` is the contract's tolerance.

Objects: the reference object and every *training* object (``objects.parquet`` split) take
part in making labels; *test* objects never do — they are only swept along the stored SKT
afterwards (``test_sweeps``), for the report.
"""

import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from skt_lib.config.rrt_skts import RrtSktsParams
from skt_lib.errors import DataError
from skt_lib.geometry.export import read_obj
from skt_lib.geometry.se3 import invert, pose_matrix
from skt_lib.io import read_table
from skt_lib.planning.collision import MeshClearance
from skt_lib.planning.probe import ProbeObject, add_probe, make_probe_collision_fn, wall_points
from skt_lib.planning.route import arm_route, route_sampler
from skt_lib.planning.smoothing import densify
from skt_lib.planning.threading import (ThreadingFailed, ThreadSettings, plan_threading,
                                        plan_threading_many)
from skt_lib.geometry.skt import executed_path, resample
from skt_lib.schemas import CONTACTS, KEYPOINTS, OBJECTS, SUPPORTS
from skt_lib.seeding import item_rng
from skt_lib.sim.world import World

BOUNDS_MARGIN_M = 0.08
#: The threading route runs this far on past the tip of the hanging arm (m).
ROUTE_BEYOND_M = 0.03
#: An SKT "reaches the hang" when its ξ_0 lies within this of the reference hang keypoint.
REACH_TOL_M = 0.005


@dataclass(frozen=True)
class SktObject:
    object_id: str
    mesh: str  # watertight visual OBJ
    collision: str  # convex parts OBJ
    keypoint: tuple[float, ...]  # 16 floats: keypoint frame in the object frame


@dataclass(frozen=True)
class SktTask:
    support_id: str
    split: str  # the support's split: test supports also get test-object sweeps
    support_urdf: str
    support_mesh: str
    reference: SktObject
    train_objects: tuple[SktObject, ...]
    test_objects: tuple[SktObject, ...]
    goal_position: tuple[float, float, float]  # reference hanging pose, support frame
    goal_quat: tuple[float, float, float, float]  # xyzw
    seed: int
    T: int  # waypoints the SKT is executed with
    params: RrtSktsParams


def _objects(mg: Path, objects, keypoints) -> dict[str, SktObject]:
    out = {}
    for o in objects.itertuples():
        if o.object_id in keypoints.index:
            k = keypoints.loc[o.object_id]
            out[o.object_id] = SktObject(o.object_id, str(mg / o.mesh_path), str(mg / o.collision_path),
                                         tuple(pose_matrix(k["position"], k["quat"]).ravel()))
    return out


def load_probe_objects(root: Path) -> tuple[SktObject, tuple[SktObject, ...],
                                            tuple[SktObject, ...]]:
    """(reference, training objects, test objects) with their keypoints, from the artifacts
    under ``root`` (the ``data/`` folder): mesh_gen and rotation_extraction outputs."""
    mg = root / "mesh_gen"
    objects = read_table(mg / "objects.parquet", OBJECTS)
    keypoints = read_table(root / "rotation_extraction" / "keypoints.parquet", KEYPOINTS)
    by_id = _objects(mg, objects, keypoints.set_index("object_id"))
    ref_ids = objects[objects["is_reference"]]["object_id"].tolist()
    if not ref_ids or ref_ids[0] not in by_id:
        raise DataError(f"{root / 'rotation_extraction' / 'keypoints.parquet'}: the reference "
                        "object has no keypoint")
    real = objects[~objects["is_reference"]]
    train = tuple(by_id[i] for i in real[real["split"] == "train"]["object_id"] if i in by_id)
    test = tuple(by_id[i] for i in real[real["split"] == "test"]["object_id"] if i in by_id)
    return by_id[ref_ids[0]], train, test


def load_skt_tasks(root: Path, seed: int, p: RrtSktsParams, T: int) -> list[SktTask]:
    """One task per support with a hanging pose, from the artifacts under ``root`` (the
    ``data/`` folder): mesh_gen, contact_sim and rotation_extraction outputs."""
    mg = root / "mesh_gen"
    supports = read_table(mg / "supports.parquet", SUPPORTS).set_index("support_id")
    contacts = read_table(root / "contact_sim" / "contacts.parquet", CONTACTS)
    reference, train, test = load_probe_objects(root)
    hangs = contacts[(contacts["kind"] == "reference_on_support") & contacts["ok"]]
    return [SktTask(h.support_id, supports.loc[h.support_id, "split"],
                    str(mg / supports.loc[h.support_id, "urdf_path"]),
                    str(mg / supports.loc[h.support_id, "mesh_path"]), reference, train, test,
                    tuple(h.hang_position), tuple(h.hang_quat), seed, T, p)
            for h in hangs.itertuples()]


def thread_settings(p: RrtSktsParams, probe_radius: float, T: int) -> ThreadSettings:
    return ThreadSettings(step_m=p.step_m, max_turn_deg=p.max_turn_deg, lead_in_m=p.lead_in_m,
                          max_release_offset_m=p.max_release_offset_m, check_step_m=p.check_step_m,
                          probe_radius_m=probe_radius, goal_bias=p.goal_bias,
                          surface_bias=p.surface_bias, max_checks=p.max_checks,
                          shortcut_steps=p.shortcut_steps, T=T, plane_bias=p.plane_bias,
                          route_bias=p.route_bias)


def surface_sampler(mesh, max_offset_m: float):
    """``sample(rng) -> (3,)``: a point on ``mesh`` (vertices, faces; area-weighted), moved
    out along its face normal by a distance uniform in ``[0, max_offset_m]`` — where a keypoint
    threaded on the support lies. Computed from the mesh alone, so imported meshes get the
    same bias."""
    tri = np.asarray(mesh.vertices, float)[np.asarray(mesh.faces)]
    cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    area = np.linalg.norm(cross, axis=1)
    cum = np.cumsum(area)
    normals = cross / np.maximum(area, 1e-30)[:, None]

    def sample(rng: np.random.Generator) -> np.ndarray:
        f = min(int(np.searchsorted(cum, rng.random() * cum[-1], side="right")), len(tri) - 1)
        a, b = rng.random(2)
        if a + b > 1.0:
            a, b = 1.0 - a, 1.0 - b
        p = tri[f, 0] + a * (tri[f, 1] - tri[f, 0]) + b * (tri[f, 2] - tri[f, 0])
        return p + normals[f] * rng.uniform(0.0, max_offset_m)

    return sample


def _kp(o: SktObject) -> np.ndarray:
    return np.asarray(o.keypoint, float).reshape(4, 4)


def _radius(mesh, keypoint: np.ndarray) -> float:
    return float(np.linalg.norm(mesh.vertices - keypoint[:3, 3], axis=1).max())


def sweep_clearance(checker: MeshClearance, frames: np.ndarray, keypoint: np.ndarray,
                    max_step_m: float | None = None) -> float:
    """Signed clearance (m, < 0: penetration) of an object whose keypoint frame follows
    ``frames (M, 4, 4)``, by the independent mesh check; ``max_step_m``: how far any point of
    the object moves at most between consecutive frames (``executed_path``'s step), which
    lets the check skip poses that cannot hold the minimum (the result is the same)."""
    return checker.clearance(frames @ invert(keypoint), max_step_m=max_step_m)


def approach_start(frames: np.ndarray, hang: np.ndarray, near_m: float) -> int:
    """Where the final approach of an executed path ``frames (M, 4, 4)`` begins: the index
    after the last frame whose keypoint lies farther than ``near_m`` from ``hang (3,)`` (0
    when none does). Test objects' sweeps are split there: within it, an object's own pose at
    the reference's hanging keypoint decides (each object settles its own way, and no path
    changes that pose); before it, the way the SKT takes does."""
    far = np.flatnonzero(np.linalg.norm(frames[:, :3, 3] - np.asarray(hang, float), axis=1) > near_m)
    return int(far[-1]) + 1 if len(far) else 0


def skt_diversity_m(keypoints: list[np.ndarray], T: int) -> float | None:
    """How much one support's SKTs differ: the mean, over pairs of SKTs, of the mean distance
    (m) between their waypoints resampled to ``T``; ``None`` with fewer than two SKTs."""
    if len(keypoints) < 2:
        return None
    w = np.stack([resample(np.asarray(k, float), T) for k in keypoints])  # (n, T, 3)
    d = np.linalg.norm(w[:, None] - w[None], axis=3).mean(axis=2)  # (n, n)
    return float(d[np.triu_indices(len(w), 1)].mean())


def n_attempts(p: RrtSktsParams, split: str) -> int:
    """SKTs planned for a support of ``split``: more for test supports, whose stored SKTs are
    the oracle's choices in ``sim_eval`` (the support's generator draws them in order: without
    the training objects the first ``n_skts_per_support`` are the ones any split would get;
    with ``probe_train_objects: test`` they are planned with the objects too)."""
    return p.n_skts_per_test_support if split == "test" else p.n_skts_per_support


#: The R_3 additive recurrence (a low-discrepancy sequence; 1/φ_3, φ_3 the root of
#: x⁴ = x + 1): start i of a support lies at (0.5 + i·α) mod 1 of its region, so the starts
#: cover the region evenly and none depends on how many are asked for.
_PHI3 = 1.2207440846057596
_R3_ALPHA = 1.0 / _PHI3 ** np.arange(1, 4)


def start_points(n: int, centre: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """``(n, 3)`` starts of a support's SKTs in the box ``[lo, hi]``: the region's centre
    ``centre`` first (exactly: it is the per-SKT planner's canonical start), then the points
    of :data:`_R3_ALPHA`'s sequence."""
    u = (0.5 + np.outer(np.arange(n), _R3_ALPHA)) % 1.0
    out = lo + u * (hi - lo)
    out[:1] = centre
    return out


def _plan(task: SktTask, goal, n: int, in_start, sample_start, lower, upper, collides, settings,
          rng, centre, box, near, route, only: list[int] | None = None):
    """``(index, dense SKT | None, failure reason | None, plan seconds, pose checks)`` for SKT
    attempts ``0 … n − 1``, by ``task.params.planner``: one tree for all (each to its own
    start; SKT 0's seconds and checks include the tree's threading) or a fresh search each
    (each to ``centre``; with ``only``, just those attempts — one tree serves all anyway)."""
    if task.params.planner == "per_skt":
        for index in range(n) if only is None else only:
            t0 = time.perf_counter()
            try:
                dense, checks = plan_threading(goal, in_start, sample_start, lower, upper,
                                               collides, settings, rng, centre, near, route)
                yield index, dense, None, time.perf_counter() - t0, checks
            except ThreadingFailed as err:
                yield index, None, err.reason, time.perf_counter() - t0, 0
        return
    t0 = time.perf_counter()
    skts = plan_threading_many(goal, start_points(n, centre, *box), in_start, sample_start,
                               lower, upper, collides, settings, rng, near, route)
    used = 0
    try:
        for index, (dense, reason, checks) in enumerate(skts):
            yield index, dense, reason, time.perf_counter() - t0, checks - used
            t0, used = time.perf_counter(), checks
    except ThreadingFailed as err:  # no tree: every attempt fails for the same reason
        spent = time.perf_counter() - t0
        for index in range(n):
            yield index, None, err.reason, spent / n, 0


def plan_support_skts(task: SktTask) -> dict:
    """All SKTs of one support (its own generator and PyBullet client). With
    ``probe_train_objects``, planned for the reference and the training objects (the latter
    away from the hang); with ``wall_train_objects``, the training objects are kept off the
    wall plane (away from the hang) whether or not they are in the probe. Attempts these
    checks leave without an SKT (a tall tip no mug clears from the start region, a curl a long
    utensil cannot follow off the wall) are planned again for the reference alone
    (:func:`fill_failed`): ``n_reference_fill`` in the result counts them, and ``probe``
    names the probe that planned the support's SKTs ("reference" where every one was).
    ``probe_train_objects: test`` plans a test support's first ``n_skts_per_support`` SKTs
    with the training objects and keeps the reference's others behind them
    (:func:`mixed_attempts`); supports of the other splits are planned for the reference."""
    p = task.params
    rng = item_rng(task.seed, "rrt_skts", task.support_id)
    ref_kp = _kp(task.reference)
    goal = pose_matrix(task.goal_position, task.goal_quat) @ ref_kp  # hanging keypoint frame
    (support_mesh,) = read_obj(task.support_mesh)
    ref_mesh = read_obj(task.reference.mesh)[0]
    ref_radius = _radius(ref_mesh, ref_kp)
    checker = MeshClearance(support_mesh, ref_mesh, p.recheck_spacing_m)
    k_goal = goal[:3, 3]
    lo_off = np.array([p.start_dx_m[0], -p.start_dy_m, p.start_dz_m[0]])
    hi_off = np.array([p.start_dx_m[1], p.start_dy_m, p.start_dz_m[1]])
    corners = np.vstack([support_mesh.vertices, k_goal + lo_off, k_goal + hi_off])
    lower, upper = corners.min(0) - BOUNDS_MARGIN_M, corners.max(0) + BOUNDS_MARGIN_M
    lower[0] = max(lower[0], 0.0)
    near = surface_sampler(support_mesh, p.surface_offset_m)
    route = (route_sampler(arm_route(support_mesh, k_goal, ROUTE_BEYOND_M), p.route_spread_m)
             if p.route_bias > 0 else None)

    def in_start(q: np.ndarray) -> bool:
        return bool(np.all(q - k_goal >= lo_off) and np.all(q - k_goal <= hi_off))

    def sample_start(g: np.random.Generator) -> np.ndarray:
        return k_goal + g.uniform(lo_off, hi_off)

    def attempts_with(world: World, obstacles: list[int], objs: tuple[SktObject, ...], wall,
                      only: list[int] | None = None, n: int | None = None) -> list:
        """The attempts (``only`` those, where the planner can; ``n`` of them, default the
        split's) planned with ``objs`` in the probe and ``wall`` points (:func:`wall_points`)
        kept off the wall."""
        probe = add_probe(world, [ProbeObject(o.collision, o.keypoint) for o in objs])
        gated = len(objs) > 1 or wall is not None
        # the per-SKT planner is kept as it was, the reference: every obstacle at every pose
        hull = (wall_points([(part, _kp(o)) for o in objs for part in read_obj(o.collision)])
                if p.planner == "one_tree" else None)
        collides = make_probe_collision_fn(world, probe, obstacles, p.clearance_m, p.penetration_tol_m,
                                           k_goal if gated else None, p.train_objects_from_m, wall,
                                           p.wall_from_m, hull)
        settings = thread_settings(p, max(_radius(read_obj(o.mesh)[0], _kp(o)) for o in objs), task.T)
        return list(_plan(task, goal, n_attempts(p, task.split) if n is None else n, in_start,
                          sample_start, lower, upper,
                          collides, settings, rng, k_goal + (lo_off + hi_off) / 2,
                          (k_goal + lo_off, k_goal + hi_off), near, route, only))

    mixed = p.probe_train_objects == "test" and task.split == "test"
    objs = (task.reference,
            *(task.train_objects if p.probe_train_objects is True or mixed else ()))
    wall = (wall_points([(read_obj(o.mesh)[0], _kp(o)) for o in task.train_objects])
            if p.wall_train_objects and task.train_objects else None)
    probe = "+".join(["objects" if len(objs) > 1 else "reference", *(["wall"] if wall is not None else [])])
    with World(dt=1 / 240, solver_iterations=1, with_floor=False) as world:
        obstacles = [world.load(task.support_urdf, np.eye(4), fixed=True, friction=0.5), world.add_wall()]

        def planned(objs: tuple[SktObject, ...]) -> tuple[list, int]:
            attempts = attempts_with(world, obstacles, objs, wall)
            failed = [a[0] for a in attempts if a[1] is None]
            if (len(objs) > 1 or wall is not None) and failed:
                return fill_failed(attempts, attempts_with(world, obstacles, objs[:1], None, failed))
            return attempts, 0

        if mixed:  # the reference's SKTs as without the objects (planned first: the same
            # draws), then the objects' for the first n_skts_per_support in front of them
            reference, n_fill = planned(objs[:1])
            n = n_attempts(p, task.split)
            attempts, n_objects_fill = mixed_attempts(
                attempts_with(world, obstacles, objs, wall, n=min(p.n_skts_per_support, n)),
                reference, n)
            n_fill += n_objects_fill
        else:
            attempts, n_fill = planned(objs)
    out = _recheck(attempts, checker, ref_kp, ref_radius, p, task.T) | {
        "probe": "reference" if n_fill == len(attempts) else probe, "n_reference_fill": n_fill}
    skts, sweeps = out["skts"], []
    if task.split == "test" and skts:  # how objects that made no label fare along the oracle SKT
        waypoints = resample(skts[0]["keypoints"], task.T)
        for o in task.test_objects:
            mesh, kp = read_obj(o.mesh)[0], _kp(o)
            frames = executed_path(waypoints, p.recheck_step_m, _radius(mesh, kp))
            checker_o = MeshClearance(support_mesh, mesh, p.recheck_spacing_m)
            k = approach_start(frames, k_goal, p.train_objects_from_m)
            way, near = (sweep_clearance(checker_o, part, kp, p.recheck_step_m) if len(part) else np.inf
                         for part in (frames[:k], frames[k:]))
            sweeps.append({"object_id": o.object_id, "clearance_m": min(way, near),
                           "clearance_on_way_m": way, "clearance_near_hang_m": near})
    return out | {"support_id": task.support_id, "n_attempted": n_attempts(p, task.split),
                  "test_sweeps": sweeps}


def fill_failed(attempts: list, fallback: list) -> tuple[list, int]:
    """(``attempts``' SKTs, then each failed attempt *i* (no path) replaced by ``fallback``'s
    attempt *i* (``fallback`` holds at least those), as attempt ``n + i`` of ``n`` — after
    every SKT of the stricter pass, so that the lowest ``skt_index`` (the oracle's first
    choice) is one of those — with the failed attempt's seconds and checks added; how many
    were replaced)."""
    n, by_index = len(attempts), {f[0]: f for f in fallback}
    kept = [a for a in attempts if a[1] is not None]
    filled = [(n + a[0], f[1], f[2], a[3] + f[3], a[4] + f[4])
              for a in attempts if a[1] is None for f in (by_index[a[0]],)]
    return kept + filled, len(filled)


def mixed_attempts(with_objects: list, reference: list, n: int) -> tuple[list, int]:
    """A test support's ``n`` attempts under ``probe_train_objects: test``: the ``m`` attempts
    planned with the training objects as attempts 0 … m − 1, the reference's attempts m … n − 1
    as they are (``reference``: all ``n``, a filled one as attempt n + i, as
    :func:`fill_failed` gives them), and each objects' attempt *i* that found no path replaced
    by the reference's attempt *i* as attempt ``n + i`` (after every other: the oracle tries
    the objects' SKTs first, then the reference's); how many were replaced."""
    m = len(with_objects)
    by_attempt = {a[0] % n: a for a in reference}
    if m > n or sorted(by_attempt) != list(range(n)) or len(reference) != n:
        raise ValueError(f"mixed_attempts: {m} attempts with the objects, the reference's "
                         f"{sorted(a[0] for a in reference)} of {n}")
    kept = [a for a in with_objects if a[1] is not None]
    filled = [(n + a[0], r[1], r[2], a[3] + r[3], a[4] + r[4])
              for a in with_objects if a[1] is None for r in (by_attempt[a[0]],)]
    return kept + [by_attempt[i] for i in range(m, n)] + filled, len(filled)


def _recheck(attempts, checker: MeshClearance, ref_kp: np.ndarray, ref_radius: float,
             p: RrtSktsParams, T: int) -> dict:
    """The planned attempts re-checked independently, as executed: ``{"skts", "failures",
    "plan_s", "recheck_s", "n_planned", "n_recheck_ok"}``."""
    skts, failures, plan_s, recheck_s = [], Counter(), [], []
    n_planned = n_recheck_ok = 0
    for index, path, reason, seconds, n_checks in attempts:
        plan_s.append(seconds)
        if path is None:
            failures[reason] += 1
            continue
        n_planned += 1
        dense = densify(path, p.dense_step_m)  # the same polyline: resampling is unchanged
        t1 = time.perf_counter()
        executed = executed_path(resample(dense, T), p.recheck_step_m, ref_radius)
        clearance = sweep_clearance(checker, executed, ref_kp, p.recheck_step_m)
        recheck_s.append(time.perf_counter() - t1)
        if clearance <= 0.0:
            failures["recheck_collision"] += 1
            continue
        n_recheck_ok += 1
        poses = executed @ invert(ref_kp)  # the reference object as executed, start first
        skts.append({"index": index, "keypoints": dense, "poses": poses[::-1], "n_checks": n_checks,
                     "min_clearance_m": clearance})
    return {"skts": skts, "failures": dict(failures), "plan_s": plan_s, "recheck_s": recheck_s,
            "n_planned": n_planned, "n_recheck_ok": n_recheck_ok}
