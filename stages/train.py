"""train — SCTDN on the training split, model selection on validation, dvclive curves.

Inputs:  data/render_views, data/affordance_maps, data/clustering (labels, templates),
         data/rrt_skts/skts.parquet, data/contact_sim/contacts.parquet; params common, train.
Outputs: data/train/sctdn.pt (state_dict) + sctdn.json (config); reports/train/live
         (dvclive metrics and plots), reports/train/{metrics.json, report.md, PNGs}.
"""

import logging
import sys
import time
from pathlib import Path

import numpy as np
import torch
from dvclive import Live

from skt_lib.config import CommonParams, load_sections
from skt_lib.config.train import TrainParams
from skt_lib.learning.data import load_training_set
from skt_lib.learning.predictor import SktPredictor
from skt_lib.learning.train import from_params, intervals, predict_items, train_sctdn
from skt_lib.seeding import item_rng
from stages._common import parse_args
from viz.figures import curves
from viz.report import Report, write_metrics, write_run_log
from viz.train_report import validation_breakdown

log = logging.getLogger("train")


def main(argv=None) -> int:
    args = parse_args("train", argv)
    params = load_sections(args.params, common=CommonParams, train=TrainParams)
    p = params.train
    root, out, rep = Path(args.data_root), Path(args.data_dir), Path(args.reports_dir)
    data = load_training_set(root)
    T, k, train, val = data.T, data.k, data.train, data.val
    cfg, settings = from_params(p, k, T, data.n_points)
    history: list[dict] = []
    t0 = time.perf_counter()
    with Live(dir=str(rep / "live"), save_dvc_exp=False, dvcyaml=None, report=None) as live:
        def on_epoch(epoch, metrics):
            for name, value in metrics.items():
                if value is not None:  # no rate where nothing was measured (see summarise)
                    live.log_metric(name, value)
            live.next_step()
            history.append(metrics)
            log.info("epoch %d: %s", epoch, {k: v if v is None else round(v, 4) for k, v in metrics.items()})

        model, best = train_sctdn(cfg, data.templates, train, val, settings,
                                  params.common.seed, on_epoch)
    wall = time.perf_counter() - t0
    predictor = SktPredictor(model)
    predictor.save(out)

    sample = val[0].points[0]
    times = []
    for _ in range(20):
        t1 = time.perf_counter()
        predictor.predict(sample)
        times.append(time.perf_counter() - t1)
    with torch.profiler.profile(activities=[torch.profiler.ProfilerActivity.CPU]) as prof:
        for _ in range(5):
            predictor.predict(sample)
    profile = prof.key_averages().table(sort_by="cpu_time_total", row_limit=12)
    items = [(s, int(v)) for s in val for v in p.val_views]
    per = predict_items(model, items)
    ci = intervals(per, [s.support_id for s, _ in items],
                   item_rng(params.common.seed, "train", "val_bootstrap"))
    curve = [h["val_traj_l2_mm"] for h in history]
    last5 = float(np.mean(curve[-5:]))
    metrics = {**best, **ci, "n_train_supports": len(train), "n_val_supports": len(val),
               "epochs": p.epochs, "release_lift_mm": 1000 * model.cfg.release_lift_m,
               "best_epoch": int(np.argmin(curve)), "val_traj_l2_mm_last5_mean": last5,
               # settled: the chosen epoch is not a lucky dip of a still-swinging curve
               "val_curve_settled": bool(best["val_traj_l2_mm"] >= 0.9 * last5)}
    write_metrics(rep, metrics)

    report = Report("train", rep)
    report.text(f"SCTDN (k = {k}, T = {T}) trained {p.epochs} epochs × {p.views_per_epoch} views per "
                f"training support ({len(train)} supports) on {torch.get_num_threads()} CPU "
                "threads (wall-clock times, the inference time and its torch.profiler breakdown: "
                f"the git-ignored run log `logs/train.json`); best epoch chosen on {len(val)} "
                f"validation supports × views {list(p.val_views)}. Each family's template is "
                f"placed with its ξ_0 {1000 * model.cfg.release_lift_m:.1f} mm above the predicted "
                "contact: the training SKTs' mean height of ξ_0 over the contact "
                "(`release_lift_mm`; docs/pipeline.md, \"The release lift\").")
    report.table(["metric (best epoch)", "value", "95 % interval", "unit"],
                 [[k2, v, _interval(ci.get(f"{k2}_ci95")), _unit(k2)] for k2, v in best.items()])
    report.text(f"Intervals: Wilson over the {len(items)} (support, view) pairs for the two rates "
                f"(it counts views as independent; they are not quite: {len(p.val_views)} views "
                f"of each support), a bootstrap over the {len(val)} supports (2000 resamples of "
                "whole supports) for the mean errors.")
    report.text("`train_*` are the training losses, averaged over the epoch: `train_traj` is the "
                "mean waypoint distance in *normalised cloud units* (cloud max radius = 1), not "
                "mm; compare training and validation on the curves, not across units.")
    curves(history, ["val_traj_l2_mm", "val_template_only_l2_mm"],
           report.figure("val_l2.png", "Validation waypoint error: SCTDN vs the aligned template"),
           "validation trajectory error", "mm")
    curves(history, ["train_loss", "train_traj", "train_aff", "train_cls"],
           report.figure("train_loss.png", "Training losses (normalised cloud units, not mm)"),
           "training", "loss (normalised units)")
    validation_breakdown(report, items, per, root)
    report.text("Curves: `dvc plots show` (reports/train/live/plots/metrics); inference speed: "
                "`make bench` (reports/bench/bench.json).")
    report.write()
    write_run_log(Path(args.log_dir), "train", {
        "wall_s": wall, "threads": torch.get_num_threads(), "inference_ms_median_batch1":
        1000 * float(np.median(times)), "inference_points": cfg.n_points,
        "profile_5_predictions": profile})
    return 0


def _interval(ci) -> str:
    """``[lo, hi]`` for the report table; a dash where the metric has no interval."""
    return "–" if ci is None else f"[{ci[0]:.3g}, {ci[1]:.3g}]"


def _unit(metric: str) -> str:
    """The unit of a training/validation figure, for the report."""
    if metric.endswith("_mm"):
        return "mm"
    if metric in ("val_cls_acc", "val_contact_within_1cm_rate"):
        return "fraction"
    if metric == "val_affordance_mse":
        return "affordance² (unitless)"
    return "normalised units (loss)"


if __name__ == "__main__":
    sys.exit(main())
