"""sim_eval — a Franka Panda hangs every test object on every test support along each
method's SKT; the strict predicate decides; Table I.

Inputs:  data/mesh_gen, data/rotation_extraction/keypoints.parquet, data/rrt_skts/skts.parquet,
         data/render_views, data/train (SCTDN); params common, compute, contact_sim (physics),
         clustering.T, sim_eval.
Outputs: data/sim_eval/trials.parquet (one row per trial), data/sim_eval/sim_eval.rrd
         (rollouts); reports/sim_eval/{metrics.json, report.md, PNGs}.
"""

import logging
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd

from skt_lib.config import LEVELS, OBJECT_CATEGORIES, load_params
from skt_lib.errors import DataError
from skt_lib.eval.methods import LEARNED, make_method
from skt_lib.eval.protocol import (
    load_test_set,
    make_task,
    predict_all,
    success_table,
    trial_settings,
)
from skt_lib.eval.stats import paired_comparisons, success_ci95, wilson_interval
from skt_lib.geometry.export import read_obj
from skt_lib.io import write_table
from skt_lib.learning.predictor import SktPredictor
from skt_lib.schemas import TRIALS
from skt_lib.sim.execute import REASONS, run_trial
from stages._common import item_store, parse_args, run_items
from viz.figures import bar_chart
from viz.report import Report, write_metrics
from viz.rollouts import log_rollouts

log = logging.getLogger("sim_eval")

#: Before the executor and planner rework (commit bc3544c: robot base (0.05, 0, 0.3),
#: horizontal grasp, SKT planned in SE(3) but executed with rule frames), as measured in the
#: executor issue on 20 test supports × 10 objects — quoted for the before/after table.
BEFORE = {"oracle success % (all / easy / normal / hard / very hard)": "26.0 / 36 / 48 / 8 / 12",
          "oracle ik_failed (share of trials)": "44 %",
          "oracle collided_before_hang (share of trials)": "27.5 %",
          "no arm (rigid hand), oracle SKT": "39.5 %"}

#: What the oracle must reach for methods to be told apart (the executor issue).
ORACLE_TARGET, ORACLE_LEVEL_TARGET = 0.90, 0.80

#: The paper's Table I (success %, SCTDN and kPAM 2.0 rows) for comparison in the report.
PAPER = {"sctdn": (83.7, 85.5, 91.7, 79.7, 77.7), "kpam": (40.1, 76.0, 54.1, 21.6, 8.8)}


def main(argv=None) -> int:
    args = parse_args("sim_eval", argv)
    params = load_params(args.params)
    p = params.sim_eval
    root, out, rep = Path(args.data_root), Path(args.data_dir), Path(args.reports_dir)
    T = params.clustering.T
    supports, objects, missing = load_test_set(root, T, params.common.seed, p.grasp_pitch_deg,
                                                p.grasp_rolls_deg)
    if not supports or not objects:
        raise DataError(f"{root}: no test supports with a ground-truth SKT or no test objects")
    predictor = None
    if any(m in LEARNED for m in p.methods):
        predictor = SktPredictor.load(root / "train")
        if predictor.cfg.T != T:
            raise DataError(f"{root / 'train'}: model predicts T = {predictor.cfg.T}, "
                            f"clustering.T is {T}")
    pre = np.asarray(p.kpam_pre_hang_m, float)
    methods = {m: (lambda s, m=m: make_method(m, predictor, s.gt, pre, p.kpam_lift_m))
               for m in p.methods}
    positions, seconds = predict_all(methods, supports)
    settings = trial_settings(p, params.contact_sim)
    tasks = [make_task(m, s, o, positions[m, s.support_id], settings)
             for m in p.methods for s in supports for o in objects]
    log.info("%d trials: %d methods × %d test supports × %d objects", len(tasks), len(p.methods),
             len(supports), len(objects))
    t0 = time.perf_counter()
    work = item_store(args)
    results, _, crashes = run_items(run_trial, tasks, params.compute, "trials", work=work)
    wall = time.perf_counter() - t0
    if crashes:
        raise RuntimeError(f"{len(crashes)} trials crashed, first: {crashes[0][0].trial_id}: "
                           f"{crashes[0][1]}")
    rows = [r["row"] for r in results]
    out.mkdir(parents=True, exist_ok=True)
    write_table(out / "trials.parquet", rows, TRIALS)
    trials = pd.DataFrame(rows)

    table = success_table(trials)
    inference_ms = {m: 1000 * float(np.median(seconds[m])) for m in p.methods}
    ci95 = success_ci95(trials, LEVELS)
    metrics = {m: {"success": table[m], "n_trials": int((trials["method"] == m).sum()),
                   "inference_ms": inference_ms[m],
                   "failures_by_reason": {r: int(((trials["method"] == m) &
                                                  (trials["failure_reason"] == r)).sum())
                                          for r in REASONS},
                   "success_ci95": ci95[m],
                   "success_by_category": _by_category(trials[trials["method"] == m])}
               for m in p.methods}
    metrics["paired"] = paired_comparisons(trials, "sctdn")
    metrics["n_test_supports"] = len(supports)
    metrics["n_test_supports_without_gt"] = len(missing)
    metrics["n_test_objects"] = len(objects)
    write_metrics(rep, metrics)

    chosen = _pick_rollouts(trials, p.n_record)
    _write_report(rep, trials, metrics, p.methods, supports, objects, missing, wall, chosen)
    by_id = {t.trial_id: t for t in tasks}
    rows_by_id = {r["trial_id"]: r for r in rows}
    s_by_id, o_by_id = {s.support_id: s for s in supports}, {o.object_id: o for o in objects}
    replay = []
    for tid in chosen:
        t = by_id[tid]
        traced = run_trial(make_task(t.method, s_by_id[t.support_id], o_by_id[t.object_id],
                                     np.asarray(t.positions), settings, p.record_every))
        if traced["row"] != rows_by_id[tid]:  # recording must not change what happened
            raise RuntimeError(f"{tid}: the recorded replay differs from the evaluated trial")
        replay.append((t, traced))
    meshes = {sid: read_obj(s_by_id[sid].mesh)[0] for sid in {t.support_id for t, _ in replay}}
    omeshes = {oid: read_obj(o_by_id[oid].mesh)[0] for oid in {t.object_id for t, _ in replay}}
    log_rollouts(out / "sim_eval.rrd", replay, meshes, omeshes, settings.robot_base)
    log.info("done: %s", {m: round(table[m]["all"], 3) for m in p.methods})
    work.finish()
    return 0


def _pick_rollouts(trials: pd.DataFrame, n: int) -> list[str]:
    """Per method: up to ``n`` successes (spread over levels) and the first trial of each
    failure reason — deterministic (table order)."""
    chosen = []
    for _, g in trials.groupby("method", sort=False):
        ok = g[g["success"]]
        chosen += list(ok.groupby("difficulty", sort=False).head(1)["trial_id"])[:n]
        chosen += list(g[~g["success"]].groupby("failure_reason", sort=False).head(1)["trial_id"])
    return chosen


def _by_category(trials: pd.DataFrame) -> dict:
    """Success rate per object category (null where the category has no trial)."""
    return {c: (float(g["success"].mean()) if len(g := trials[trials["category"] == c]) else None)
            for c in OBJECT_CATEGORIES}


def _pct(x) -> str:
    return "–" if x is None else f"{100 * x:.1f}"


def _pct_ci(rate, ci) -> str:
    """``52.0 [45.1–58.8]``: a success rate (%) with its Wilson 95 % interval."""
    return "–" if rate is None or ci is None else f"{_pct(rate)} [{_pct(ci[0])}–{_pct(ci[1])}]"


def _rate_ci(success: pd.Series) -> str:
    ci = wilson_interval(int(success.sum()), len(success))
    return _pct_ci(float(success.mean()) if len(success) else None, ci)


def _write_report(rep: Path, trials: pd.DataFrame, metrics: dict, methods, supports, objects,
                  missing, wall: float, chosen: list[str]) -> None:
    report = Report("sim_eval", rep)
    n = len(trials)
    report.text(
        f"{n} trials ({len(methods)} methods × {len(supports)} test supports × {len(objects)} "
        f"objects) in {wall / 60:.1f} min ({n / wall * 60:.0f} trials/min on this machine). "
        "A trial: the Panda holds the object at its grasp (fixed keypoint→hand transform), "
        "follows the SKT from ξ_T-1 to ξ_0 (all of it, ≤ 2 mm per command, joint position "
        "control), releases, retreats; gravity is tilted ±y, +x and settled; the strict "
        "predicate (DESIGN §5) decides. Each method sees one seeded view of each support. "
        + (f"Test supports without a ground-truth SKT, left out: {', '.join(missing)}." if missing else ""))
    report.heading("Table I: success rate (%) [Wilson 95 % interval] and inference time")
    rows = [[m, f"{metrics[m]['inference_ms']:.2f}",
             *(_pct_ci(metrics[m]["success"][k], metrics[m]["success_ci95"][k])
               for k in ("all", *LEVELS))] for m in methods]
    rows += [[f"paper: {m}", "9" if m == "sctdn" else "–", *(f"{v:.1f}" for v in vals)]
             for m, vals in PAPER.items()]
    report.table(["method", "inference (ms)", "All", "Easy", "Normal", "Hard", "Very Hard"], rows)
    report.text("Inference: median per support, batch 1, CPU, measured apart from the simulation. "
                "`oracle` and `kpam` are privileged (ground-truth SKT / hanging keypoint). "
                "Brackets: Wilson 95 % score interval of the rate; trials on one support are "
                "correlated, so the intervals are if anything too narrow. Paper rows have none.")
    _paired_table(report, metrics.get("paired", {}))
    _before_after(report, metrics)
    bar_chart({m: {lv: 100 * (metrics[m]["success"][lv] or 0) for lv in ("all", *LEVELS)}
               for m in methods}, report.figure("success.png", "Success rate (%) per level"),
              "success rate (%)")
    report.heading("Per object category (success %, paper Table III layout)")
    cats = [c for c in OBJECT_CATEGORIES if c in set(trials["category"])]
    report.table(["method", *cats], [[m, *(_rate_ci(trials.loc[(trials["method"] == m)
                                                            & (trials["category"] == c), "success"])
                                           for c in cats)] for m in methods])
    report.heading("Failure reasons")
    counts = {m: {r: metrics[m]["failures_by_reason"][r] for r in REASONS} for m in methods}
    report.table(["method", *REASONS], [[m, *counts[m].values()] for m in methods])
    bar_chart(counts, report.figure("failures.png", "Failure reasons per method (trial counts)"),
              "failures")
    report.text("`ik_failed`: no grasp candidate lets the hand follow the path within tolerance "
                "(kinematics; `detail` in trials.parquet says which check); "
                "`collided_before_hang`: the object or robot is blocked by the support or wall "
                "on the way in; `not_reached`: released, never touched the support; `dropped`: "
                "touched it, then fell; `not_at_rest`: on the support but still moving at the "
                "end; `on_wall_plate`: resting on the wall plate only; `perched`: rests on top; "
                "`touches_robot`: still on the gripper. `oracle_floating` has no arm: it cannot "
                "fail by `ik_failed`.")
    report.heading("Per level (success % [Wilson 95 %], trials)")
    n_by_level = trials.groupby(["method", "difficulty"]).size()
    report.table(["method", *LEVELS],
                 [[m, *(f"{_pct_ci(metrics[m]['success'][lv], metrics[m]['success_ci95'][lv])}, "
                        f"n = {int(n_by_level.get((m, lv), 0))}" for lv in LEVELS)]
                  for m in methods])
    report.heading("Per support")
    per = trials.pivot_table(index=["support_id", "difficulty"], columns="method", values="success",
                             aggfunc="mean").reset_index()
    report.table(["support", "level", *methods],
                 [[r["support_id"], r["difficulty"], *(_pct(r[m]) for m in methods)]
                  for _, r in per.iterrows()])
    report.recording("trial")
    report.text(f"{len(chosen)} rollouts (robot, object, SKT with its waypoint frames, the "
                "keypoint's executed path, its distance from the SKT): per method a few successes "
                "and the first trial of each failure reason. The `trial` timeline shows each "
                "trial's end state; scrub `step` to replay a rollout.")
    report.write()


def _before_after(report: Report, metrics: dict) -> None:
    if "oracle" not in metrics:
        return
    o = metrics["oracle"]
    share = {r: o["failures_by_reason"][r] / max(1, o["n_trials"]) for r in REASONS}
    now = [" / ".join(_pct(o["success"][k]) for k in ("all", *LEVELS)),
           f"{100 * share['ik_failed']:.1f} %", f"{100 * share['collided_before_hang']:.1f} %",
           f"{_pct(metrics['oracle_floating']['success']['all'])} % (`oracle_floating`)"
           if "oracle_floating" in metrics else "–"]
    report.heading("Oracle before / after the executor and planner rework")
    report.table(["measure", "before (bc3544c)", "now"],
                 [[k, v, a] for (k, v), a in zip(BEFORE.items(), now)])
    short = [lv for lv in LEVELS if (o["success"][lv] or 0.0) < ORACLE_LEVEL_TARGET]
    gap = ORACLE_TARGET - o["success"]["all"]
    report.text(
        f"Target: oracle ≥ {100 * ORACLE_TARGET:.0f} % overall and ≥ "
        f"{100 * ORACLE_LEVEL_TARGET:.0f} % per level. Overall: "
        + (f"{100 * gap:.1f} points below the target" if gap > 0 else "met")
        + (f"; levels below target: {', '.join(short)}" if short else "") + ". "
        + ("Where `oracle_floating` (no arm) fails too, the SKT is the limit, not the arm: "
           "on hooks whose tip rises ≥ ~3 cm with a ~90°+ turn the planner can only release "
           "in front of the tip and the object drops (README, rrt_skts, 'Known limit')."
           if short else ""))


def _paired_table(report: Report, paired: dict) -> None:
    """The paired comparisons (same trials, exact McNemar): "A beats B" only where it holds."""
    report.heading("Paired comparisons (same support × object trials, exact McNemar, α = 0.05)")
    if not paired:
        report.text("No paired comparisons: `sctdn` was not evaluated.")
        return
    rows = []
    for key, c in paired.items():
        a, b = key.split("_vs_", 1)
        verdict = {"A better": f"{a} better", "B better": f"{b} better"}.get(c["verdict"],
                                                                             c["verdict"])
        rows.append([f"{a} vs {b}", c["n_pairs"], c["n_both"], c["n_a_only"], c["n_b_only"],
                     f"{c['p_value']:.3g}", verdict])
    report.table(["comparison", "pairs", "both ok", "A only", "B only", "p", "verdict"], rows)
    report.text("A only / B only: trials only the first / second method hung. The verdict "
                "names a winner only where p < 0.05; otherwise the difference in Table I is "
                "not evidence that one method beats the other.")


if __name__ == "__main__":
    sys.exit(main())
