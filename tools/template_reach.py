"""Why the template methods fail on Very Hard hooks (``make train-diagnostics``, after
``make repro``): how far a support's ground-truth SKTs lie from its family's template, and
how far the committed SCTDN deforms the template toward them.

SCTDN places its family's template at the predicted contact and adds learned offsets. That
can only work where some ground-truth SKT of the support lies near the template, or where the
network learns offsets as large as the gap. Written to ``reports/train/template_reach.{json,
md,png}``:

- **label geometry**, per level of the validation supports: the distance (mean waypoint
  distance, both SKTs taken relative to their ξ_0) from a support's nearest ground-truth SKT
  to its own family's template, for the committed clustering and for the same clustering
  refitted with other ``k`` (the training split, the committed seed): how much of the gap more
  families would close; and to the nearest SKT of any training support, the floor that no
  template drawn from the training SKTs can beat;
- **the committed model** (``data/train``), per level on the validation views: the template
  aligned at the predicted contact and the deformed SKT, each against its nearest
  ground-truth SKT, and the size of the deformation itself (mean waypoint offset);
- **a template retrieved per hook** by the committed encoder: the training support whose
  deformation feature (the affordance-masked shape feature, mean over all its views) is
  nearest by cosine to the view's, its SKT nearest to the predicted family's template,
  aligned at the predicted contact; and, optimistically, the best of that support's SKTs
  against the ground truth — whether the encoder's features could choose a closer template
  than the family's (docs/pipeline.md, the lead it tests);
- **a picture**: the Very Hard validation support whose gap is the median of its level, seen
  from the side (support x–z) and from above (x–y): its cloud, its ground-truth SKTs, the
  aligned template and the deformed SKT.

Not part of ``dvc repro`` and not a DVC output: a documented run whose numbers
docs/pipeline.md quotes.
"""

import argparse
import json
import sys
from pathlib import Path

import numpy as np
import torch

from skt_lib.config import LEVELS
from skt_lib.config.params_file import load_params
from skt_lib.geometry.skt import resample
from skt_lib.io import read_table
from skt_lib.labels.families import fit_families
from skt_lib.learning.data import load_supports, normalise
from skt_lib.learning.predictor import SktPredictor
from skt_lib.learning.sctdn import backbone_features, masked_max_pool
from skt_lib.schemas import SKTS, SUPPORTS
from skt_lib.seeding import item_rng

#: ``k`` refitted besides the committed one.
OTHER_K = (8, 12, 16)


def gap_to_templates(skts: np.ndarray, templates: np.ndarray) -> np.ndarray:
    """``(k,)`` mm: for each template ``(k, T, 3)`` (relative to ξ_0), the mean waypoint
    distance of the nearest of ``skts (G, T, 3)`` (each taken relative to its own ξ_0)."""
    rel = skts - skts[:, :1]
    return 1000 * np.linalg.norm(rel[:, None] - templates[None], axis=-1).mean(-1).min(0)


def label_gaps(root: Path, T: int, k_values, seed: int, n_init: int, max_iter: int) -> dict:
    """Per ``k``: the median per level (validation supports) of :func:`gap_to_templates` to
    the support's own family, and the training families' sizes; and under
    ``any_training_skt`` the same to the nearest SKT of any training support."""
    sup = read_table(root / "mesh_gen" / "supports.parquet", SUPPORTS).set_index("support_id")
    rows = read_table(root / "rrt_skts" / "skts.parquet", SKTS)
    paths = {sid: [np.stack(k) for k in g.sort_values("skt_index")["keypoints"]]
             for sid, g in rows.groupby("support_id")}
    train = {sid for sid in paths if sup.loc[sid, "split"] == "train"}
    val = sorted(sid for sid in paths if sup.loc[sid, "split"] == "val")
    pool = np.concatenate([np.stack([resample(q, T) for q in paths[sid]])
                           for sid in sorted(train)])
    floor: dict[str, list] = {}
    for sid in val:  # the nearest SKT of any training support: what no template beats
        skts = np.stack([resample(p, T) for p in paths[sid]])
        for lv in (sup.loc[sid, "difficulty"], "all"):
            gap = gap_to_templates(pool, skts - skts[:, :1]).min()
            floor.setdefault(lv, []).append(float(gap))
    medians = {lv: float(np.median(g)) for lv, g in floor.items()}
    out: dict = {"any_training_skt": {"gap_mm_median": medians}}
    for k in (k for k in k_values if k <= len(train)):  # k-means needs k training supports
        fam = fit_families(paths, train, T, k, item_rng(seed, "clustering", "kmeans"), n_init,
                           max_iter)
        gaps: dict[str, list] = {}
        for sid in val:
            skts = np.stack([resample(p, T) for p in paths[sid]])
            gap = gap_to_templates(skts, fam.templates)[fam.labels[sid]]
            for lv in (sup.loc[sid, "difficulty"], "all"):
                gaps.setdefault(lv, []).append(float(gap))
        out[str(k)] = {"gap_mm_median": {lv: float(np.median(g)) for lv, g in gaps.items()},
                       "family_sizes": np.bincount(fam.train_labels, minlength=k).tolist()}
    return out


@torch.no_grad()
def shape_keys(model, points: np.ndarray) -> np.ndarray:
    """``(V, C)``: the deformation's shape feature (affordance-masked max pool of the
    encoder's point features, as ``Sctdn._deform``) of each view ``points (V, N, 3)``."""
    xyz_n, _, _ = normalise(points.astype(np.float64))
    _, feats = backbone_features(model, torch.as_tensor(xyz_n, dtype=torch.float32))
    aff = torch.sigmoid(model.aff_head(feats)[:, 0])
    return masked_max_pool(feats, aff, model.cfg.aff_threshold).double().numpy()


def retrieve(keys: np.ndarray, query: np.ndarray) -> int:
    """Index of the row of ``keys (S, C)`` nearest to ``query (C,)`` by cosine."""
    a = keys / np.linalg.norm(keys, axis=1, keepdims=True)
    return int(np.argmax(a @ (query / np.linalg.norm(query))))


@torch.no_grad()
def model_gaps(predictor: SktPredictor, val, views, train) -> tuple[dict, dict]:
    """Per level (and ``all``), medians over validation views (mm): the aligned template's
    and the deformed SKT's distance to the nearest ground-truth SKT (``template_mm``,
    ``sctdn_mm``), the deformation's size (``offset_mm``), and the template retrieved from
    the ``train`` supports (:func:`retrieve` on :func:`shape_keys`): the retrieved support's
    SKT nearest to the predicted family's template (``retrieved_mm``) and the best of its
    SKTs (``retrieved_best_mm``, optimistic: it looks at the ground truth); and per support
    its template gap with its SKTs (metres, support frame) for the picture."""
    model, rows, shown = predictor.model.eval(), {}, {}
    keys = np.stack([shape_keys(model, s.points).mean(0) for s in train])
    lift = np.array([0.0, 0.0, model.cfg.release_lift_m])
    for s in val:
        for v in views:
            pts = s.points[int(v)].astype(np.float64)
            xyz_n, c, scale = normalise(pts)
            out = model(torch.as_tensor(xyz_n[None], dtype=torch.float32),
                        torch.as_tensor([scale], dtype=torch.float32))
            aligned = out["aligned"][0].double().numpy() * scale + c
            traj = out["trajectory"][0].double().numpy() * scale + c
            near = lambda p: 1000 * np.linalg.norm(s.skts - p, axis=-1).mean(-1).min()  # noqa: E731
            found = train[retrieve(keys, shape_keys(model, pts[None])[0])].skts
            found = found - found[:, :1]  # relative to ξ_0, as a template
            template = model.templates[out["logits"][0].argmax()].double().numpy()
            placed = aligned[0] - template[0] + found  # at the predicted contact and lift
            nearest = placed[np.argmin(np.linalg.norm(found - template, axis=-1).mean(-1))]
            r = (near(aligned), near(traj), 1000 * np.linalg.norm(traj - aligned, axis=-1).mean(),
                 near(nearest), min(near(q) for q in placed))
            for lv in (s.level, "all"):
                rows.setdefault(lv, []).append(r)
            if int(v) == int(views[0]):
                shown[s.support_id] = {"level": s.level, "template_mm": r[0], "points": pts,
                                       "skts": s.skts, "aligned": aligned, "trajectory": traj}
    table = {lv: dict(zip(("template_mm", "sctdn_mm", "offset_mm", "retrieved_mm",
                           "retrieved_best_mm"),
                          np.median(np.array(r), axis=0).tolist()), n_views=len(r))
             for lv, r in rows.items()}
    return table, shown


def picture(shown: dict, path: Path) -> str:
    """The support of median template gap on the hardest level there is (Very Hard on any
    real preset): side and top views; its id."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    level = next(lv for lv in reversed(LEVELS) if any(d["level"] == lv for d in shown.values()))
    vh = sorted((d["template_mm"], sid) for sid, d in shown.items() if d["level"] == level)
    sid = vh[len(vh) // 2][1]
    d = shown[sid]
    fig, axes = plt.subplots(1, 2, figsize=(10, 4.2))
    for ax, (i, j, name) in zip(axes, ((0, 2, "side (x–z)"), (0, 1, "above (x–y)"))):
        ax.scatter(d["points"][:, i], d["points"][:, j], s=2, c="0.7", label="cloud (view)")
        for n, skt in enumerate(d["skts"]):
            ax.plot(skt[:, i], skt[:, j], c="tab:green", lw=1,
                    label="ground-truth SKTs" if n == 0 else None)
        ax.plot(d["aligned"][:, i], d["aligned"][:, j], c="tab:orange", lw=2,
                label="template at the predicted contact")
        ax.plot(d["trajectory"][:, i], d["trajectory"][:, j], c="tab:blue", lw=2, ls="--",
                label="SCTDN (deformed)")
        ax.scatter(*d["aligned"][0, [i, j]], c="k", marker="x", zorder=5)
        ax.set(title=f"{sid} from {name}", xlabel="xyz"[i] + " (m)", ylabel="xyz"[j] + " (m)",
               aspect="equal")
    axes[0].legend(fontsize=7, loc="best")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return sid


def markdown(d: dict) -> str:
    k0 = str(d["k"])
    lines = ["# Template reach", "",
             "Written by `tools/template_reach.py` (`make train-diagnostics`) on the committed "
             "params and the artifacts of `make repro`.", "",
             "**The labels**: per level of the validation supports, the median distance (mean "
             "waypoint, each SKT relative to its ξ_0) from a support's nearest ground-truth SKT "
             f"to its family's template; k = {k0} is the committed clustering, the others refit "
             "on the training split with the committed seed.", "",
             "| k | training family sizes | " + " | ".join(LEVELS) + " | all |",
             "|---|---|" + "---|" * (len(LEVELS) + 1)]
    for k, r in d["labels"].items():
        g = r["gap_mm_median"]
        name = "any training SKT (the floor)" if k == "any_training_skt" else k
        sizes = r.get("family_sizes", "–")
        lines.append(f"| {name}{' (committed)' if k == k0 else ''} | {sizes} | "
                     + " | ".join(f"{g.get(lv, float('nan')):.1f}" for lv in (*LEVELS, "all"))
                     + " |")
    lines += ["", "**The committed model**, validation views, medians (mm): the template "
              "aligned at the predicted contact and the deformed SKT against the nearest "
              "ground-truth SKT, how far the deformation moved the template, and a template "
              "retrieved per hook from the training supports by the encoder's shape feature "
              "(the retrieved support's SKT nearest to the predicted family's template, at the "
              "predicted contact; and the best of its SKTs, which looks at the ground truth):",
              "", "| level | views | template | SCTDN | deformation | retrieved | retrieved, "
              "best of its SKTs (optimistic) |", "|---|---|---|---|---|---|---|"]
    for lv in (*LEVELS, "all"):
        if lv in d["model"]:
            r = d["model"][lv]
            lines.append(f"| {lv} | {r['n_views']} | {r['template_mm']:.1f} | "
                         f"{r['sctdn_mm']:.1f} | {r['offset_mm']:.1f} | "
                         f"{r['retrieved_mm']:.1f} | {r['retrieved_best_mm']:.1f} |")
    lines += ["", f"![{d['picture']}](template_reach.png)", "",
              f"`{d['picture']}` (the validation support of median template gap on the "
              "hardest level, its first validation view): the cloud, its ground-truth SKTs, the "
              "template at the "
              "predicted contact (× its ξ_0) and SCTDN's deformed SKT.", ""]
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--params", default="params.yaml")
    ap.add_argument("--data-root", default="data", type=Path)
    ap.add_argument("--out", default="reports/train", type=Path)
    args = ap.parse_args(argv)
    params = load_params(args.params)
    pc, seed = params.clustering, params.common.seed
    d = {"k": pc.k, "labels": label_gaps(args.data_root, pc.T, (pc.k, *OTHER_K), seed,
                                          pc.n_init, pc.max_iter)}
    supports = load_supports(args.data_root, pc.T)
    val = [s for s in supports if s.split == "val"]
    d["model"], shown = model_gaps(SktPredictor.load(args.data_root / "train"), val,
                                   params.train.val_views,
                                   [s for s in supports if s.split == "train"])
    args.out.mkdir(parents=True, exist_ok=True)
    d["picture"] = picture(shown, args.out / "template_reach.png")
    (args.out / "template_reach.json").write_text(json.dumps(d, indent=2, sort_keys=True) + "\n")
    (args.out / "template_reach.md").write_text(markdown(d))
    print(f"wrote {args.out / 'template_reach.md'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
