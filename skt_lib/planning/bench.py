"""The planner bench of ``make bench`` (``stages/bench.py``): the one-tree planner and the
per-SKT reference on the same supports, timed in one run."""

import dataclasses
import time
from pathlib import Path

import numpy as np

from skt_lib.config import LEVELS
from skt_lib.io import read_table
from skt_lib.planning.skts import load_skt_tasks, plan_support_skts, skt_diversity_m
from skt_lib.schemas import SUPPORTS


def rrt_bench(params, root: Path, per_level: int, n_skts: int, run_items) -> dict:
    """Both planners on the same supports (``per_level`` of each level), ``n_skts`` SKTs
    each, re-check included, timed in this run: the one-tree planner (``rrt_*``) and the
    per-SKT reference (``rrt_*_reference``), their ratio, and each one's SKT diversity per
    level (:func:`~skt_lib.planning.skts.skt_diversity_m`). ``run_items``: the stages' runner
    (``stages._common.run_items``), which spreads supports over ``compute.n_workers``."""
    supports = read_table(root / "mesh_gen" / "supports.parquet", SUPPORTS).set_index("support_id")
    p = params.rrt_skts.model_copy(update={"n_skts_per_support": n_skts,
                                           "n_skts_per_test_support": n_skts})
    all_tasks = load_skt_tasks(root, params.common.seed, p, params.clustering.T)
    # the hardest level first, as the stage orders its longest items: a very hard support
    # started last holds one worker while the other idles (both planners get this order)
    chosen = [t for lv in reversed(LEVELS)
              for t in [t for t in all_tasks if supports.loc[t.support_id, "difficulty"] == lv][:per_level]]
    out = {"rrt_bench_supports": len(chosen), "rrt_bench_skts_per_support": n_skts}
    for planner, suffix in (("per_skt", "_reference"), ("one_tree", "")):
        tasks = [dataclasses.replace(t, split="train",  # no test-object sweeps: the same work
                                     params=p.model_copy(update={"planner": planner})) for t in chosen]
        t0 = time.perf_counter()
        results, _, _ = run_items(plan_support_skts, tasks, params.compute, f"bench rrt, {planner}")
        wall = time.perf_counter() - t0
        n = sum(len(r["skts"]) for r in results)
        by_level = {lv: [skt_diversity_m([s["keypoints"] for s in r["skts"]], params.clustering.T)
                         for r in results if supports.loc[r["support_id"], "difficulty"] == lv]
                    for lv in LEVELS}
        out |= {
            f"rrt_plan_s_median{suffix}": float(np.median([t for r in results for t in r["plan_s"]])),
            f"rrt_recheck_s_median{suffix}": float(np.median([t for r in results for t in r["recheck_s"]])),
            f"rrt_skts_per_min{suffix}": 60.0 * n / wall,
            f"rrt_bench_skts{suffix}": n,
            f"rrt_diversity_mm{suffix}": {lv: 1000 * float(np.mean([d for d in v if d is not None]))
                                          if any(d is not None for d in v) else None
                                          for lv, v in by_level.items()},
        }
    out["rrt_speedup_vs_reference_planner"] = out["rrt_skts_per_min"] / out["rrt_skts_per_min_reference"]
    return out
