"""sim_eval — a Franka Panda hangs every test object on every test support along each
method's SKT; the strict predicate decides; Table I.

Inputs:  data/mesh_gen, data/rotation_extraction/keypoints.parquet, data/rrt_skts/skts.parquet,
         data/render_views, data/train (SCTDN); params common, compute, contact_sim (physics),
         clustering.T, sim_eval; reports/seeds/seed_runs.json (the learned methods' outcomes
         under the extra training seeds, ``make seeds``: merged into ``metrics["seeds"]``
         when made from the same inputs, see :mod:`skt_lib.eval.seeds`).
Outputs: data/sim_eval/trials.parquet (one row per trial), data/sim_eval/sim_eval.rrd
         (rollouts); reports/sim_eval/{metrics.json, report.md, PNGs}.
"""

import logging
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

from skt_lib.config import CommonParams, ComputeParams, load_sections
from skt_lib.config.clustering import ClusteringParams
from skt_lib.config.contact_sim import ContactSimParams
from skt_lib.config.render_views import RenderViewsParams
from skt_lib.config.rrt_skts import RrtSktsParams
from skt_lib.config.sim_eval import SimEvalParams
from skt_lib.coverage import multimodality_coverage
from skt_lib.errors import DataError
from skt_lib.eval.methods import MODEL_OF, load_models, method_for
from skt_lib.eval.metrics import sim_metrics
from skt_lib.eval.probe_check import load_probes
from skt_lib.eval.protocol import (
    load_test_set,
    per_pair,
    predict_all,
    reference_points,
    trial_settings,
)
from skt_lib.eval.rounds import pick_rollouts, replay, run_rounds
from skt_lib.eval.seeds import seed_block
from skt_lib.eval.user_items import load_user_items, run_user_trials, user_metrics
from skt_lib.geometry.export import read_obj
from skt_lib.io import write_table
from skt_lib.schemas import TRIALS
from skt_lib.sim.execute import run_trial
from stages._common import item_store, parse_args, run_items
from viz.report import write_metrics, write_run_log
from viz.rollouts import log_rollouts
from viz.sim_eval_report import write_report

log = logging.getLogger("sim_eval")


def main(argv=None) -> int:
    args = parse_args("sim_eval", argv)
    params = load_sections(args.params, common=CommonParams, compute=ComputeParams,
                           contact_sim=ContactSimParams, clustering=ClusteringParams,
                           rrt_skts=RrtSktsParams, render_views=RenderViewsParams,
                           sim_eval=SimEvalParams)
    p = params.sim_eval
    root, out, rep = Path(args.data_root), Path(args.data_dir), Path(args.reports_dir)
    T = params.clustering.T
    supports, objects, missing = load_test_set(root, T, params.common.seed, p.grasp_pitch_deg,
                                                p.grasp_rolls_deg, p.grasp_yaws_deg,
                                                grasp_sphere=p.grasp_sphere_directions)
    if not supports or not objects:
        raise DataError(f"{root}: no test supports with a ground-truth SKT or no test objects")
    models = load_models(root, p.methods, T)
    omni_points = reference_points(root) if "omnihang" in p.methods else None
    probes = load_probes(root) if "skt_flow" in p.methods else None
    seed = params.common.seed
    extra_s, extra_o, user_md5 = load_user_items(root, params)
    positions, seconds, made, fallbacks = predict_all(
        {m: (lambda s, m=m: method_for(m, s.support_id, s.gt, params, models, omni_points,
                                                   probes=probes))
         for m in p.methods}, [*supports, *extra_s])
    fallbacks = {key: f[:p.setup_fallbacks] for key, f in fallbacks.items()}
    settings = trial_settings(p, params.contact_sim)
    log.info("%d (method, test support, object) pairs: %d methods × %d test supports × %d "
             "objects; proposing methods run up to %d proposals per pair",
             len(p.methods) * len(supports) * len(objects), len(p.methods), len(supports),
             len(objects), p.n_proposals)
    work = item_store(args)

    def run(tasks, label: str, resumable: bool = True) -> list[dict]:
        results, _, crashes = run_items(run_trial, tasks, params.compute, label,
                                        work=work if resumable else None)
        if crashes:
            raise RuntimeError(f"{len(crashes)} trials crashed, first: {crashes[0][0].trial_id}: "
                               f"{crashes[0][1]}")
        return results

    t0 = time.perf_counter()
    rows, tasks = run_rounds(p.methods, supports, objects, positions, settings, run, fallbacks)
    user_rows = run_user_trials(p.methods, supports, objects, extra_s, extra_o, positions,
                                settings, run, fallbacks)
    wall = time.perf_counter() - t0
    out.mkdir(parents=True, exist_ok=True)
    write_table(out / "trials.parquet", rows, TRIALS)
    trials = pd.DataFrame(rows)
    pairs = per_pair(trials)
    plans = {s.support_id: made["omnihang", s.support_id].last
             for s in supports} if "omnihang" in p.methods else None
    metrics = sim_metrics(trials, pairs, p.methods, p.n_proposals, plans, seed)
    metrics["multimodality_coverage"] = multimodality_coverage(
        positions, supports, [m for m in p.methods if m in MODEL_OF], p.n_proposals)
    metrics["n_test_supports"] = len(supports)
    metrics["n_test_supports_without_gt"] = len(missing)
    metrics["n_test_objects"] = len(objects)
    if p.extra_supports or p.extra_objects:
        write_table(out / "user_trials.parquet", user_rows, TRIALS)
        metrics["user_items"] = user_metrics(user_rows, p.methods, user_md5)
    metrics["seeds"] = seed_block(pairs, seed, rep.parent / "seeds" / "seed_runs.json",
                                  Path(args.params).parent)
    if metrics["seeds"]["status"] != "ok":
        log.warning("Table I over training seeds: %s", metrics["seeds"]["reason"])
    write_metrics(rep, metrics)
    write_run_log(Path(args.log_dir), "sim_eval", {
        "wall_s": wall, "n_trials": len(trials), "trials_per_min": 60 * len(trials) / wall,
        "inference_ms_median": {m: 1000 * float(np.median(seconds[m])) for m in p.methods}})

    chosen = pick_rollouts(trials, p.n_record, p.methods)
    write_report(rep, trials, pairs, metrics, p.methods, supports, objects, missing, chosen)
    replayed = replay(chosen, tasks, rows, settings, p.record_every,
                      lambda ts, label: run(ts, label, resumable=False))  # traces: not kept
    s_mesh = {s.support_id: s.mesh for s in supports}
    o_mesh = {o.object_id: o.mesh for o in objects}
    log_rollouts(out / "sim_eval.rrd", replayed,
                 {t.support_id: read_obj(s_mesh[t.support_id])[0] for t, _ in replayed},
                 {t.object_id: read_obj(o_mesh[t.object_id])[0] for t, _ in replayed},
                 settings.robot_base)
    log.info("done: %s", {m: round(metrics[m]["success"]["all"], 3) for m in p.methods})
    work.finish()
    return 0


if __name__ == "__main__":
    sys.exit(main())
