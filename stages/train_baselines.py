"""train_baselines — the learned baselines of Table I and Table II, trained with SCTDN's loop,
data, validation split and budget (the ``train`` params), one seed.

- ``sctdn_cp_feature``: SCTDN whose deformation is conditioned on the contact-point feature
  instead of the shape-conditioned one (Table II, middle row);
- ``vatmart``: affordance + CVAE on the contact-point feature, KL ``vatmart_kl_weight``;
- ``vatmart_mod``: the same CVAE on the shape-conditioned feature, KL ``vatmart_mod_kl_weight``;
- ``skt_flow``: conditional flow matching over the SKT's control points
  (:mod:`skt_lib.learning.flow`), its samples ordered by the cloud check.

Inputs:  as ``train``; params common.seed, train, train_baselines, sim_eval.n_proposals.
Outputs: data/train_baselines/<model>/ (``sctdn.pt``+``sctdn.json``, ``vatmart.pt``+
         ``vatmart.json`` or ``skt_flow.pt``+``skt_flow.json``); reports/train_baselines/{metrics.json, report.md, PNGs}.
"""

import logging
import sys
import time
from pathlib import Path

import numpy as np
from tqdm import tqdm

from skt_lib.config import CommonParams, load_sections
from skt_lib.config.proposals import ProposalsOnly
from skt_lib.config.train import TrainParams
from skt_lib.config.train_baselines import TrainBaselinesParams
from skt_lib.learning.data import load_training_set
from skt_lib.learning.pointnet2 import geometry_memo
from skt_lib.learning.train import from_params
from skt_lib.learning.train_baselines import train_baseline
from stages._common import parse_args
from viz.figures import curves
from viz.report import Report, write_metrics, write_run_log

log = logging.getLogger("train_baselines")


def main(argv=None) -> int:
    args = parse_args("train_baselines", argv)
    params = load_sections(args.params, common=CommonParams, train=TrainParams,
                           train_baselines=TrainBaselinesParams, sim_eval=ProposalsOnly)
    p, pb = params.train, params.train_baselines
    root, out, rep = Path(args.data_root), Path(args.data_dir), Path(args.reports_dir)
    sets = {v: load_training_set(root, v) for v in sorted({pb.views.get(m, "clean")
                                                            for m in pb.models})}
    any_set = next(iter(sets.values()))  # the families, waypoints and points are the same
    cfg, settings = from_params(p, any_set.k, any_set.T, any_set.n_points)
    n_prop = params.sim_eval.n_proposals
    metrics, histories, walls = {}, {}, {}
    with geometry_memo():  # the same views for every model: each cloud searched once
        for name in tqdm(pb.models, desc="baselines", unit="model"):
            seed = params.common.seed  # SCTDN's: the same view order, the same initial backbone
            history: list[dict] = []

            def on_epoch(epoch, m, name=name, history=history):
                history.append(m)
                log.info("%s epoch %d: %s", name, epoch,
                         {k2: v if v is None else round(v, 4) for k2, v in m.items()})

            t0 = time.perf_counter()
            data = sets[pb.views.get(name, "clean")]
            predictor, best = train_baseline(name, cfg, data.templates, data.train, data.val,
                                             settings, seed, n_prop, pb, on_epoch)
            predictor.save(out / name)
            walls[name] = time.perf_counter() - t0
            curve = [h["val_traj_l2_mm"] for h in history]
            metrics[name] = {**best, "best_epoch": int(np.argmin(curve)), "epochs": p.epochs}
            histories[name] = history
    write_metrics(rep, metrics)
    _write_report(rep, metrics, histories, len(any_set.train), len(any_set.val), p, n_prop,
                  {m: pb.views.get(m, "clean") for m in pb.models})
    write_run_log(Path(args.log_dir), "train_baselines", {"wall_s": walls})
    return 0


def _write_report(rep: Path, metrics: dict, histories: dict, n_train: int, n_val: int, p,
                  n_prop: int, views: dict[str, str]) -> None:
    report = Report("train_baselines", rep)
    report.text(f"Learned baselines trained like SCTDN (`train`): {p.epochs} epochs × "
                f"{p.views_per_epoch} views per training support ({n_train} supports), best epoch "
                f"chosen on {n_val} validation supports × views {list(p.val_views)} "
                "(never on training supports); wall-clock times: the git-ignored run log "
                "`logs/train_baselines.json`.")
    keys = sorted({k for m in metrics.values() for k in m if k.startswith("val_")})
    report.table(["model", "views", *keys, "best epoch"],
                 [[m, views[m], *("–" if v.get(k) is None else v[k] for k in keys),
                   v["best_epoch"]] for m, v in metrics.items()])
    report.text("Views (`train_baselines.views`): `clean` = `render_views`' ring, Table I's "
                "views; `sensor` = its depth-camera views of the training and validation "
                "supports (`render_views.sensor_views_severity`), trained and selected on; "
                "`both` = the two in one pool, each epoch's views drawn from either, selected "
                "on the clean validation views.")
    report.text("`val_traj_l2_mm`: mean waypoint distance (mm) of the prediction to the nearest "
                "ground-truth SKT, contact from the predicted affordance; for the CVAEs it is "
                f"one proposal (the first of {n_prop} fixed validation latents), "
                f"`val_best_of_n_l2_mm` the best of the {n_prop} (the paper's best-of-10 "
                "counts a trial as hung if any proposal hangs), `val_spread_mm` the mean "
                "distance of the proposals from their mean (0: the latent is ignored). "
                f"`skt_flow`: `val_traj_l2_mm` is the one of {n_prop} samples (fixed validation "
                "noise) that the cloud check ranks first — the SKT it executes; "
                "`val_first_l2_mm` the first sample, unchecked; `val_coverage_1cm` the share "
                "of a support's ground-truth SKTs some sample comes within 1 cm of. The epoch "
                "is chosen on `val_traj_l2_mm` for every model.")
    for m, h in histories.items():
        curves(h, [k for k in ("val_traj_l2_mm", "val_first_l2_mm", "val_best_of_n_l2_mm",
                               "val_template_only_l2_mm") if k in h[0]],
               report.figure(f"val_l2_{m}.png", f"{m}: validation waypoint error per epoch"),
               m, "mm")
    report.write()


if __name__ == "__main__":
    sys.exit(main())
