"""Where do objects collide along the stored SKTs, and which SKT would clear them?
(``python -m tools.object_sweeps``, after ``make repro``'s ``rrt_skts``.)

``rrt_skts`` plans with the reference ring alone and reports ``test_sweep_clear_rate``: the
share of (test support, test object) pairs whose object, swept along the support's SKT 0 by
the exact mesh check, penetrates support or wall by at most ``SWEEP_TOL_M``. This tool
sweeps every object of the set (training and test) along **every** stored SKT of each
support of ``--split`` and prints:

- the stage's rate, recomputed (SKT 0, test objects);
- the rate if each support's SKTs were ordered by the *training* objects' sweeps (most
  objects clear first, then the shallowest deepest penetration): a planner may use those;
- the best any stored SKT gives (the test object's own best: an upper bound of reordering);
- where the failing SKT-0 pairs penetrate deepest: at the hang (the object's keypoint at the
  reference's hang pose; no path fixes that), in the first or the second half of the path.

``--out`` writes every sweep as JSON. Nothing under the data root or ``reports/`` changes.
"""

import argparse
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from skt_lib.config.params_file import load_params
from skt_lib.geometry.export import read_obj
from skt_lib.geometry.skt import executed_path, resample
from skt_lib.geometry.se3 import invert
from skt_lib.io import read_table, write_json_atomic
from skt_lib.planning.collision import MeshClearance
from skt_lib.planning.skts import SktObject, load_probe_objects
from skt_lib.schemas import SKTS, SUPPORTS
from stages._common import run_items
from stages.rrt_skts import SWEEP_TOL_M

#: A failing pair's deepest pose lies "at the hang" when it is this far along the path or more.
AT_HANG = 0.97


@dataclass(frozen=True)
class SweepTask:
    support_id: str
    support_mesh: str
    skts: tuple[np.ndarray, ...]  # stored keypoint paths, ξ_0 first, in SKT order
    objects: tuple[tuple[str, SktObject], ...]  # (kind: "train" / "test", object)
    T: int
    spacing_m: float
    step_m: float


def object_sweeper(support, o: SktObject, spacing_m: float, step_m: float):
    """``(checker, poses)`` for object ``o`` against the ``support`` mesh: its
    :class:`MeshClearance` at ``spacing_m``, and ``poses(positions)``, the keypoint frames of
    the SKT ``positions (T, 3)`` as executed (:func:`executed_path` at ``step_m``, far end
    first) and the object frames there, ``(keypoint frames, object frames)``."""
    mesh = read_obj(o.mesh)[0]
    kp = np.asarray(o.keypoint, float).reshape(4, 4)
    radius = float(np.linalg.norm(mesh.vertices - kp[:3, 3], axis=1).max())

    def poses(positions: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        keypoint_frames = executed_path(positions, step_m, radius)
        return keypoint_frames, keypoint_frames @ invert(kp)

    return MeshClearance(support, mesh, spacing_m), poses


def sweep_support(task: SweepTask) -> dict:
    """Every object along every SKT of one support: ``{"support_id", "sweeps": [{object_id,
    kind, skt, clearance_m, deepest_at}]}``; ``deepest_at`` (share of the path from its
    start, 1 = the hang) for test objects on SKT 0, else ``None``."""
    (support,) = read_obj(task.support_mesh)
    rows = []
    for kind, o in task.objects:
        checker, along = object_sweeper(support, o, task.spacing_m, task.step_m)
        for index, keypoints in enumerate(task.skts):
            _, poses = along(resample(keypoints, task.T))
            at = None
            if kind == "test" and index == 0:  # every pose: where the deepest one lies
                per_pose = checker.per_pose(poses)
                clearance, at = float(per_pose.min()), float(per_pose.argmin() / max(1, len(poses) - 1))
            else:
                clearance = checker.clearance(poses, max_step_m=task.step_m)
            rows.append({"object_id": o.object_id, "kind": kind, "skt": index,
                         "clearance_m": clearance, "deepest_at": at})
    return {"support_id": task.support_id, "sweeps": rows}


def clear(clearance_m: float) -> bool:
    return clearance_m >= -SWEEP_TOL_M


def train_order(sweeps: list[dict]) -> list[int]:
    """A support's SKT indices ordered by its training objects' sweeps: most objects clear
    first, then the largest smallest clearance, then the index."""
    skts = sorted({s["skt"] for s in sweeps})
    train = {k: [s["clearance_m"] for s in sweeps if s["skt"] == k and s["kind"] == "train"] for k in skts}
    return sorted(skts, key=lambda k: (-sum(map(clear, train[k])), -min(train[k], default=np.inf), k))


def summarise(results: list[dict]) -> dict:
    """The figures the module docstring lists, over the supports' results."""
    skt0, ordered, best, where = [], [], [], {"hang": 0, "first_half": 0, "second_half": 0}
    for r in results:
        test = [s for s in r["sweeps"] if s["kind"] == "test"]
        first = train_order(r["sweeps"])[0]
        for oid in sorted({s["object_id"] for s in test}):
            mine = {s["skt"]: s for s in test if s["object_id"] == oid}
            skt0.append(clear(mine[0]["clearance_m"]))
            ordered.append(clear(mine[first]["clearance_m"]))
            best.append(any(clear(s["clearance_m"]) for s in mine.values()))
            if not skt0[-1]:
                at = mine[0]["deepest_at"]
                where["hang" if at >= AT_HANG else "first_half" if at < 0.5 else "second_half"] += 1
    rate = (lambda v: float(np.mean(v)) if v else None)
    return {"n_supports": len(results), "n_pairs": len(skt0), "test_sweep_clear_rate": rate(skt0),
            "clear_rate_ordered_by_train_objects": rate(ordered),
            "clear_rate_best_stored_skt": rate(best), "failing_pairs_deepest_at": where,
            "sweep_tol_m": SWEEP_TOL_M}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="tools/object_sweeps.py", description=__doc__.splitlines()[0])
    ap.add_argument("--params", default="params.yaml", type=Path)
    ap.add_argument("--data-root", default="data", type=Path)
    ap.add_argument("--split", default="test", choices=("train", "val", "test", "all"))
    ap.add_argument("--out", type=Path, help="every sweep and the summary, as JSON")
    args = ap.parse_args(argv)
    params = load_params(args.params)
    root, p = args.data_root, params.rrt_skts
    supports = read_table(root / "mesh_gen" / "supports.parquet", SUPPORTS).set_index("support_id")
    skts = read_table(root / "rrt_skts" / "skts.parquet", SKTS)
    _, train, test = load_probe_objects(root)
    objects = (*(("train", o) for o in train), *(("test", o) for o in test))
    tasks = []
    for sid, group in skts.groupby("support_id", sort=True):
        if args.split != "all" and supports.loc[sid, "split"] != args.split:
            continue
        paths = tuple(np.asarray(k.tolist(), float) for k in group.sort_values("skt_index")["keypoints"])
        tasks.append(SweepTask(sid, str(root / "mesh_gen" / supports.loc[sid, "mesh_path"]), paths,
                               objects, params.clustering.T, p.recheck_spacing_m, p.recheck_step_m))
    if not tasks:
        print(f"ERROR: no SKTs of a {args.split} support under {root / 'rrt_skts'}", file=sys.stderr)
        return 2
    results, _, crashed = run_items(sweep_support, tasks, params.compute, "supports")
    if len(results) < len(tasks):
        done = {r["support_id"] for r in results}
        print(f"ERROR: sweeps failed on {[t.support_id for t in tasks if t.support_id not in done]}"
              + (f": {crashed[0][1]}" if crashed else ""), file=sys.stderr)
        return 1
    results.sort(key=lambda r: r["support_id"])
    summary = summarise(results)
    for key, value in summary.items():
        print(f"{key}: {value}")
    if args.out:
        write_json_atomic(args.out, {"summary": summary, "supports": results})
    return 0


if __name__ == "__main__":
    sys.exit(main())
