"""rrt_skts — threaded SKTs into every support, ending at the hang, valid as executed (SKT
frames at T).

Inputs:  data/mesh_gen (supports, objects and their split), data/contact_sim/contacts.parquet
         (hanging poses), data/rotation_extraction/keypoints.parquet (keypoint frames);
         params common, compute, rrt_skts, clustering.T (the executed resolution).
Outputs: data/rrt_skts/skts.parquet (dense SKTs, ξ_0 at the release), rrt_skts.rrd;
         reports/rrt_skts/{metrics.json, report.md, PNGs}.
"""

import logging
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np

from skt_lib.config import LEVELS, CommonParams, ComputeParams, load_sections
from skt_lib.config.rrt_skts import RrtSktsParams
from skt_lib.config.waypoints import WaypointsOnly
from skt_lib.geometry.export import read_obj
from skt_lib.geometry.se3 import matrix_pose, pose_matrix
from skt_lib.geometry.skt import arc_length
from skt_lib.io import read_table, write_table
from skt_lib.planning.skts import REACH_TOL_M, load_skt_tasks, plan_support_skts, skt_diversity_m
from skt_lib.schemas import OBJECTS, SKTS, SUPPORTS
from stages._common import item_store, parse_args, run_items
from viz.report import write_metrics
from viz.rrt_skts_report import log_skts, write_report

log = logging.getLogger("rrt_skts")
#: A test object's sweep along the oracle SKT is "clear" when it penetrates at most this much
#: (measured on the earlier SKTs: every trial whose sweep stayed within 3 mm hung).
SWEEP_TOL_M = 0.003

def main(argv=None) -> int:
    args = parse_args("rrt_skts", argv)
    params = load_sections(args.params, common=CommonParams, compute=ComputeParams,
                           rrt_skts=RrtSktsParams, clustering=WaypointsOnly)
    p, seed = params.rrt_skts, params.common.seed
    root, out, rep = Path(args.data_root), Path(args.data_dir), Path(args.reports_dir)
    supports = read_table(root / "mesh_gen" / "supports.parquet", SUPPORTS).set_index("support_id")
    ref = read_table(root / "mesh_gen" / "objects.parquet", OBJECTS).query("is_reference").iloc[0]
    tasks = load_skt_tasks(root, seed, p, params.clustering.T)
    mg = root / "mesh_gen"
    t0 = time.perf_counter()
    work = item_store(args)
    # the longest items first — test supports (their object sweeps), then the harder levels:
    # a long item started last leaves a core idle at the end (results are keyed by support)
    hardest = {lv: -i for i, lv in enumerate(LEVELS)}
    longest_first = sorted(tasks, key=lambda t: (t.split != "test",
                                                 hardest[supports.loc[t.support_id, "difficulty"]]))
    results, crash_counts, crashed = run_items(plan_support_skts, longest_first, params.compute,
                                               "supports", work=work)
    rank = {t.support_id: i for i, t in enumerate(tasks)}
    results.sort(key=lambda r: rank[r["support_id"]])  # back in support order
    wall = time.perf_counter() - t0
    by_task = {r["support_id"]: r for r in results}  # never pair tasks with results by position

    rows, xi0_err, reached = [], [], Counter()
    for task in tasks:
        if task.support_id not in by_task:
            continue
        r = by_task[task.support_id]
        kp = np.asarray(task.reference.keypoint).reshape(4, 4)
        k_goal = (pose_matrix(task.goal_position, task.goal_quat) @ kp)[:3, 3]
        for s in r["skts"]:
            pos_quat = [matrix_pose(t) for t in s["poses"]]
            xi0_err.append(float(np.linalg.norm(s["keypoints"][0] - k_goal)))
            if xi0_err[-1] > REACH_TOL_M:  # not an SKT of this support (docs/design.md §3)
                continue
            reached[supports.loc[r["support_id"], "difficulty"]] += 1
            rows.append({"support_id": r["support_id"], "skt_index": s["index"],
                         "n_states": len(s["poses"]), "keypoints": s["keypoints"].tolist(),
                         "positions": [q[0].tolist() for q in pos_quat],
                         "quats": [q[1].tolist() for q in pos_quat],
                         "path_length_m": float(arc_length(s["keypoints"])[-1]),
                         "min_clearance_m": s["min_clearance_m"], "n_checks": s["n_checks"]})
    write_table(out / "skts.parquet", rows, SKTS)
    n_off_hang = len(xi0_err) - len(rows)

    plan_s = [t for r in results for t in r["plan_s"]]
    n_attempted = sum(r["n_attempted"] for r in results)
    n_planned, n_recheck_ok = sum(r["n_planned"] for r in results), sum(r["n_recheck_ok"] for r in results)
    failures = sum((Counter(r["failures"]) for r in results), Counter())
    sweeps = [w["clearance_m"] for r in results for w in r["test_sweeps"]]
    clear = {part: [w[f"clearance_{part}_m"] >= -SWEEP_TOL_M for r in results for w in r["test_sweeps"]]
             for part in ("on_way", "near_hang")}
    level = supports["difficulty"]
    by_level = {lv: reached[lv] for lv in LEVELS}
    attempted_by_level = Counter()
    for r in results:
        attempted_by_level[level[r["support_id"]]] += r["n_attempted"]
    paths = {}  # support → its stored SKTs' keypoints
    for row in rows:
        paths.setdefault(row["support_id"], []).append(np.asarray(row["keypoints"]))
    diversity = {lv: [] for lv in LEVELS}
    for sid, kps in paths.items():
        d = skt_diversity_m(kps, params.clustering.T)
        if d is not None:
            diversity[level[sid]].append(1000 * d)
    metrics = {
        "n_supports": len(tasks), "n_supports_with_skts": len({r["support_id"] for r in rows}),
        "n_skts": len(rows), "n_attempted": n_attempted,
        "plan_success_rate": len(rows) / max(1, n_attempted),
        "reaches_hang_rate": len(rows) / max(1, n_attempted),
        "reaches_hang_rate_by_level": {lv: reached[lv] / max(1, attempted_by_level[lv]) for lv in LEVELS},
        "recheck_collision_free_rate": n_recheck_ok / max(1, n_planned),
        "xi0_error_max_m": max(xi0_err, default=None),
        "xi0_error_median_m": float(np.median(xi0_err)) if xi0_err else None,
        "skts_by_difficulty": by_level,
        "skt_diversity_mm_by_level": {lv: float(np.mean(v)) if v else None for lv, v in diversity.items()},
        "failures_by_reason": dict(sorted((failures + Counter(
            {"off_hang": n_off_hang} if n_off_hang else {})).items())),
        "n_supports_crashed": len(crashed),
        # attempts the training objects' checks left without an SKT, planned for the reference alone
        "n_supports_object_probe_fallback": sum(r["n_reference_fill"] > 0 for r in results),
        "n_attempts_reference_fill": sum(r["n_reference_fill"] for r in results),
        "crashes_by_reason": dict(sorted(crash_counts.items())),
        "test_sweep_clear_rate": float(np.mean([c >= -SWEEP_TOL_M for c in sweeps])) if sweeps else None,
        # split where the final approach (train_objects_from_m of the hang) begins: planning
        # decides the way there; within it, each object's own pose at the shared hanging keypoint
        **{f"test_sweep_clear_rate_{part}": float(np.mean(v)) if v else None for part, v in clear.items()},
        "test_sweep_n_pairs": len(sweeps),
        "test_sweep_clearance_mm_median": 1000 * float(np.median(sweeps)) if sweeps else None,
    }
    write_metrics(rep, metrics)

    meshes = {sid: read_obj(mg / supports.loc[sid, "mesh_path"])[0] for sid in {t.support_id for t in tasks}}
    log_skts(out / "rrt_skts.rrd", results, supports, meshes, read_obj(mg / ref.mesh_path)[0])
    write_report(rep, params, metrics, results, supports, meshes, attempted_by_level, reached,
                 failures, sweeps, SWEEP_TOL_M)
    log.info("%.1f s wall, median plan %.3f s", wall, float(np.median(plan_s or [0])))
    log.info("%d SKTs, reach the hang %.3f, recheck %.3f", len(rows), metrics["reaches_hang_rate"],
             metrics["recheck_collision_free_rate"])
    work.finish()
    return 0


if __name__ == "__main__":
    sys.exit(main())
