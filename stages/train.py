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

from skt_lib.config import load_params
from skt_lib.errors import DataError
from skt_lib.io import read_npz
from skt_lib.learning.data import load_supports
from skt_lib.learning.predictor import SktPredictor
from skt_lib.learning.sctdn import SctdnConfig
from skt_lib.learning.train import TrainSettings, train_sctdn
from stages._common import parse_args
from viz.figures import curves
from viz.report import Report, write_metrics

log = logging.getLogger("train")


def main(argv=None) -> int:
    args = parse_args("train", argv)
    params = load_params(args.params)
    p = params.train
    root, out, rep = Path(args.data_root), Path(args.data_dir), Path(args.reports_dir)
    tz = read_npz(root / "clustering" / "templates.npz", {"templates": ("float64", 3)})
    T, k = int(tz["T"]), int(tz["k"])
    supports = load_supports(root, T)
    train = [s for s in supports if s.split == "train"]
    val = [s for s in supports if s.split == "val"]
    if not train or not val:
        raise DataError(f"{root / 'mesh_gen'}: {len(train)} training and {len(val)} validation "
                        "supports with labels; model selection needs both (set "
                        "mesh_gen.n_val_per_level ≥ 1) — it never selects on training supports")
    cfg = SctdnConfig(k=k, T=T, n_points=supports[0].points.shape[1])
    settings = TrainSettings(p.epochs, p.views_per_epoch, p.batch_size, p.lr, p.weight_decay,
                             tuple(p.val_views))
    history: list[dict] = []
    t0 = time.perf_counter()
    with Live(dir=str(rep / "live"), save_dvc_exp=False, dvcyaml=None, report=None) as live:
        def on_epoch(epoch, metrics):
            for name, value in metrics.items():
                live.log_metric(name, value)
            live.next_step()
            history.append(metrics)
            log.info("epoch %d: %s", epoch, {k: round(v, 4) for k, v in metrics.items()})

        model, best = train_sctdn(cfg, tz["templates"], train, val, settings,
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
    metrics = {**best, "n_train_supports": len(train), "n_val_supports": len(val),
               "epochs": p.epochs, "inference_ms_median": 1000 * float(np.median(times))}
    write_metrics(rep, metrics)

    report = Report("train", rep)
    report.text(f"SCTDN (k = {k}, T = {T}) trained {p.epochs} epochs × {p.views_per_epoch} views per "
                f"training support ({len(train)} supports) in {wall / 60:.1f} min on "
                f"{torch.get_num_threads()} CPU threads; best epoch chosen on {len(val)} validation "
                f"supports × views {list(p.val_views)}.")
    report.table(["metric (best epoch)", "value", "unit"],
                 [[k2, v, _unit(k2)] for k2, v in best.items()])
    report.text("`train_*` are the training losses, averaged over the epoch: `train_traj` is the "
                "mean waypoint distance in *normalised cloud units* (cloud max radius = 1), not "
                "mm; compare training and validation on the curves, not across units.")
    curves(history, ["val_traj_l2_mm", "val_template_only_l2_mm"],
           report.figure("val_l2.png", "Validation waypoint error: SCTDN vs the aligned template"),
           "validation trajectory error", "mm")
    curves(history, ["train_loss", "train_traj", "train_aff", "train_cls"],
           report.figure("train_loss.png", "Training losses (normalised cloud units, not mm)"),
           "training", "loss (normalised units)")
    report.text(f"Inference (batch 1, {cfg.n_points} points in → SKT out, model loaded): median "
                f"{metrics['inference_ms_median']:.1f} ms. Curves: `dvc plots show` "
                f"(reports/train/live/plots/metrics).")
    report.heading("Where inference time goes (torch.profiler, 5 predictions)")
    report.text("```\n" + profile + "\n```")
    report.write()
    return 0


def _unit(metric: str) -> str:
    """The unit of a training/validation figure, for the report."""
    if metric.endswith("_mm"):
        return "mm"
    if metric == "val_cls_acc":
        return "fraction"
    if metric == "val_affordance_mse":
        return "affordance² (unitless)"
    return "normalised units (loss)"


if __name__ == "__main__":
    sys.exit(main())
