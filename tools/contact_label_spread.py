"""How reproducible is the contact label? (``python -m tools.contact_label_spread``, after
``make repro``'s ``mesh_gen``.)

``contact_sim`` labels each support with the contact point of the reference object's hang
(the medoid of ``n_drops`` releases). A label the network is asked to predict from a view
of the support should be a function of the support: here the reference drops are run again
with other seeds (``--seeds``; the drops' release poses and physics are otherwise the
stage's), and each support's label spread is the largest distance between its labels over
the seeds. Printed per level and family; ``--out`` writes every support's labels and spread
as JSON. Nothing under the data root or ``reports/`` changes.
"""

import argparse
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from skt_lib.config.params_file import load_params
from skt_lib.io import read_table, write_json_atomic
from skt_lib.schemas import OBJECTS, SUPPORTS
from skt_lib.sim.contact_sim import eval_damping, reference_task, simulate_hangs
from stages._common import run_items

#: A spread above this (m) is a label that moves more than the 1 cm the contact metric allows.
SPREAD_TOL_M = 0.01


def label_spread(labels: list[np.ndarray]) -> float:
    """Largest pairwise distance (m) between a support's contact labels ``(3,)``."""
    c = np.asarray(labels, float)
    return float(np.linalg.norm(c[:, None] - c[None], axis=-1).max()) if len(c) > 1 else 0.0


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="tools/contact_label_spread.py",
                                 description=__doc__.splitlines()[0])
    ap.add_argument("--params", default="params.yaml", type=Path)
    ap.add_argument("--data-root", default="data", type=Path)
    ap.add_argument("--split", default="val", choices=["train", "val", "test", "all"])
    ap.add_argument("--seeds", type=int, nargs="+", default=None,
                    help="drop seeds (default: common.seed and the next two)")
    ap.add_argument("--out", type=Path, default=None)
    args = ap.parse_args(argv)
    params = load_params(args.params)
    p = params.contact_sim
    seeds = args.seeds or [params.common.seed + i for i in range(3)]
    if len(seeds) < 2:
        print("ERROR: --seeds: a spread needs at least two seeds", file=sys.stderr)
        return 2
    src = args.data_root / "mesh_gen"
    supports = read_table(src / "supports.parquet", SUPPORTS)
    if args.split != "all":
        supports = supports[supports["split"] == args.split]
    if supports.empty:
        print(f"ERROR: {src}: no {args.split} supports", file=sys.stderr)
        return 2
    objects = read_table(src / "objects.parquet", OBJECTS)
    ref = objects[objects["is_reference"]].iloc[0]
    tasks = [reference_task(s, ref, src, seed, p, eval_damping(params)) for seed in seeds
             for s in supports.itertuples()]
    rows, _, failed = run_items(simulate_hangs, tasks, params.compute, "reference drops")
    labels: dict[str, list] = {}
    for r in rows:
        if r["ok"]:
            labels.setdefault(r["item_id"], []).append(r["contact_support"])
    info = supports.set_index("support_id")
    table = pd.DataFrame([(sid, info.loc[sid, "difficulty"], info.loc[sid, "family"],
                           1000 * label_spread(c)) for sid, c in labels.items() if len(c) > 1],
                         columns=["support_id", "level", "family", "spread_mm"])
    n_failed = len(tasks) - sum(r["ok"] for r in rows)
    print(f"{len(supports)} {args.split} supports × seeds {seeds}: {n_failed} of {len(tasks)} "
          f"drop runs found no hang ({len(failed)} crashed)")
    for key in ("level", "family"):
        print(table.groupby(key)["spread_mm"].agg(
            supports="size", median_mm="median", max_mm="max",
            over_1cm=lambda x: int((x > 1000 * SPREAD_TOL_M).sum())).round(2).to_string(), "\n")
    if args.out:
        write_json_atomic(args.out, {"seeds": seeds, "split": args.split, "n_failed_runs": n_failed,
                                     "supports": {r.support_id: {"level": r.level, "family": r.family,
                                                                 "spread_mm": r.spread_mm,
                                                                 "labels": labels[r.support_id]}
                                                  for r in table.itertuples()}})
    return 0


if __name__ == "__main__":
    sys.exit(main())
