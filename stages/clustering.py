"""clustering — SKT template families (PCA + k-means on the training split).

Inputs:  data/rrt_skts/skts.parquet, data/mesh_gen/supports.parquet; params common, clustering.
Outputs: data/clustering/labels.parquet (family per support, all splits), templates.npz
         (templates (k, T, 3) float64 relative to ξ_0, template_support_ids (k,) str,
         pca_mean (3T,), pca_components (2, 3T), centres (k, 2), T, k), clustering.rrd;
         reports/clustering/{metrics.json, report.md, scatter.png, agreement.png, templates.png}.

``skt_family_agreement``: mean, over supports with at least two SKTs (all splits), of the
share of a support's SKTs whose nearest centre is the support's (majority) family — how far
the family is a property of the support rather than of the individual SKT.
"""

import logging
import sys
from pathlib import Path

import numpy as np

from skt_lib.config import CommonParams, load_sections
from skt_lib.config.clustering import ClusteringParams
from skt_lib.geometry.export import read_obj
from skt_lib.io import read_table, write_npz_atomic, write_table
from skt_lib.labels.families import fit_families
from skt_lib.schemas import LABELS, SKTS, SUPPORTS
from skt_lib.seeding import item_rng
from stages._common import parse_args
from viz.figures import Panel, agreement_scatter, mesh_gallery, scatter_2d
from viz.report import Report, write_metrics
from viz.rerun_log import log_scatter_2d, log_strip, recording

log = logging.getLogger("clustering")


def main(argv=None) -> int:
    args = parse_args("clustering", argv)
    params = load_sections(args.params, common=CommonParams, clustering=ClusteringParams)
    p = params.clustering
    root, out, rep = Path(args.data_root), Path(args.data_dir), Path(args.reports_dir)
    supports = read_table(root / "mesh_gen" / "supports.parquet", SUPPORTS).set_index("support_id")
    skts = read_table(root / "rrt_skts" / "skts.parquet", SKTS)
    paths = {sid: [np.stack(k) for k in g.sort_values("skt_index")["keypoints"]]
             for sid, g in skts.groupby("support_id")}
    train = {sid for sid in paths if supports.loc[sid, "split"] == "train"}
    fam = fit_families(paths, train, p.T, p.k, item_rng(params.common.seed, "clustering", "kmeans"),
                       p.n_init, p.max_iter)

    rows = [{"support_id": sid, "split": supports.loc[sid, "split"],
             "difficulty": supports.loc[sid, "difficulty"], "category": int(fam.labels[sid]),
             "n_skts": len(paths[sid]), "embedding": fam.embeddings[sid].tolist(),
             "is_template": sid in fam.template_support_ids} for sid in sorted(paths)]
    write_table(out / "labels.parquet", rows, LABELS)
    write_npz_atomic(out / "templates.npz", {
        "templates": fam.templates, "template_support_ids": np.array(fam.template_support_ids),
        "pca_mean": fam.pca.mean, "pca_components": fam.pca.components, "centres": fam.centres,
        "T": np.int64(p.T), "k": np.int64(p.k)})
    sizes = [int((fam.train_labels == j).sum()) for j in range(p.k)]
    multi = [sid for sid in sorted(paths) if len(paths[sid]) >= 2]
    # None (JSON null) when no support has two SKTs to agree
    agreement = float(np.mean([fam.agreement[sid] for sid in multi])) if multi else None
    by_split = {split: float(np.mean([fam.agreement[s] for s in multi if supports.loc[s, "split"] == split]))
                for split in sorted({supports.loc[s, "split"] for s in multi})}
    metrics = {"k": p.k, "T": p.T, "cluster_sizes": sizes, "silhouette": fam.silhouette,
               "skt_family_agreement": agreement, "skt_family_agreement_by_split": by_split,
               "n_supports_agreement": len(multi),
               "n_train_supports": len(train), "n_train_skts": int(len(fam.train_labels)),
               "supports_by_category": [sum(r["category"] == j for r in rows) for j in range(p.k)]}
    write_metrics(rep, metrics)

    with recording("clustering", out / "clustering.rrd", "clustering: templates") as rec:
        for j, t in enumerate(fam.templates):
            log_strip(rec, f"world/templates/{j}", t + [0.0, 0.15 * j, 0.0], static=True)
        log_scatter_2d(rec, "plots/pca/skts", fam.train_xy, fam.train_labels, static=True)
        log_scatter_2d(rec, "plots/pca/centres", fam.centres, np.arange(p.k),
                       labels=[f"family {j}" for j in range(p.k)], static=True)
    report = Report("clustering", rep)
    report.text(f"{metrics['n_train_skts']} SKTs of {len(train)} training supports, T = {p.T}, "
                f"k = {p.k}; cluster sizes {sizes}; silhouette {fam.silhouette:.3f}. Templates from "
                f"{', '.join(fam.template_support_ids)}.")
    scatter_2d(fam.train_xy, fam.train_labels, report.figure("scatter.png", "Training SKTs in PCA "
               "space (×: centres), as the paper's Fig. 4b"), "SKT families", fam.centres)
    xy = np.vstack([fam.skt_embeddings[sid] for sid in sorted(paths)])
    sup_fam = np.concatenate([[fam.labels[sid]] * len(paths[sid]) for sid in sorted(paths)])
    own = ((xy[:, None] - fam.centres[None]) ** 2).sum(2).argmin(1)
    report.text(f"Family agreement (share of a support's SKTs in its majority family, mean over the "
                f"{len(multi)} supports with ≥ 2 SKTs, all splits): **{agreement if agreement is None else round(agreement, 3)}** "
                f"({', '.join(f'{k} {v:.3f}' for k, v in by_split.items())}).")
    agreement_scatter(xy, sup_fam, own, fam.centres, report.figure(
        "agreement.png", "Every SKT (all splits) coloured by its support's family; red rings: SKTs "
        "nearer another family's centre"), "Does the support decide the family?")
    report.table(["family", "template support", "train SKTs", "supports (all splits)"],
                 [[j, fam.template_support_ids[j], sizes[j], metrics["supports_by_category"][j]]
                  for j in range(p.k)])
    panels = []
    for j, sid in enumerate(fam.template_support_ids):
        (m,) = read_obj(root / "mesh_gen" / supports.loc[sid, "mesh_path"])
        start = paths[sid][0][0]
        panels.append(Panel(f"family {j}: {sid}", [(m.vertices, m.faces, (0.35, 0.22, 0.12, 1.0))],
                            lines=[fam.templates[j] + start]))
    mesh_gallery(panels, report.figure("templates.png", "Template SKT of each family on its support"))
    report.write()
    log.info("k=%d sizes=%s silhouette=%.3f", p.k, sizes, fam.silhouette)
    return 0


if __name__ == "__main__":
    sys.exit(main())
