"""Why SCTDN learns what it learns (``make train-diagnostics``, after ``make repro``).

Short, seeded training runs on the pipeline's artifacts, with the committed ``params.yaml``
except where a run says otherwise; results in ``reports/train/diagnostics.{json,md}``:

- **overfit one batch**: 16 training views, ``steps`` Adam steps, teacher forcing off for
  the read-out: the trajectory error should go to ~0 (the model can represent the labels);
- **learning curve**: the first ¼, ½ and all training supports (sorted ids), the same
  ``epochs`` each, validation error of the last epoch;
- **contact term**: the same short run with ``contact_weight`` 0 (the paper's loss) and the
  committed value — the template is placed at the argmax of the affordance, so where that
  misses the contact the template (and the deformation built on it) miss too;
- **train vs val** for the committed model (``data/train``): the same metrics on the
  training supports' validation views, no teacher forcing;
- **what the errors come from** (committed model, validation views): the trajectory and
  hang (ξ_0) errors with the predicted family and contact, with the true family given, and
  with both given — how much of the error each prediction adds;
- **where the contact misses** (committed model, validation views that show the contact):
  each miss (> 1 cm) split into its component along the hanging arm at the hang (the
  generator's ``hang_tangent``, ``supports.parquet``) and across it, per level;
- **per level** (committed model, validation views): the trajectory error over the whole SKT
  and over its ``HANG_END`` waypoints nearest the hang (where millimetres decide a threading),
  the ξ_0 error, the classifier's accuracy and confusion, the contact, and the same
  trajectory errors with the true family and contact given.

Not part of ``dvc repro`` (minutes on 2 cores) and not a DVC output: a documented run whose
numbers the train report quotes.
"""

import argparse
import dataclasses
import json
import sys
import time
from pathlib import Path

import numpy as np
import torch

from skt_lib.config import LEVELS
from skt_lib.config.params_file import load_params
from skt_lib.io import read_npz, read_table
from skt_lib.learning.data import load_supports
from skt_lib.learning.predictor import SktPredictor
from skt_lib.learning.sctdn import Sctdn, sctdn_loss, traj_distance
from skt_lib.learning.train import (CONTACT_OK_M, TrainSettings, evaluate, from_params,
                                    make_batch, train_sctdn)
from skt_lib.schemas import SUPPORTS


def overfit_one_batch(cfg, templates, train, seed: int, steps: int) -> dict:
    rng = np.random.default_rng(seed)
    items = [(train[i], int(rng.integers(train[i].points.shape[0])))
             for i in rng.choice(len(train), size=min(16, len(train)), replace=False)]
    b = make_batch(items)
    with torch.random.fork_rng():
        torch.manual_seed(seed)
        model = Sctdn(cfg, torch.as_tensor(templates))
        opt = torch.optim.Adam(model.parameters(), 1e-3)
        first = None
        for _ in range(steps):
            model.train()
            out = model(b["xyz"], b["scale"], b["family"], b["contact"])
            loss, parts = sctdn_loss(out, b["gt"], b["valid"], b["aff"], b["family"], b["contact_target"])
            first = first or parts
            opt.zero_grad()
            loss.backward()
            opt.step()
    scale_mm = float(b["scale"].mean()) * 1000
    return {"n_views": len(items), "steps": steps, "traj_first_mm": first["traj"] * scale_mm,
            "traj_last_mm": parts["traj"] * scale_mm, "cls_last": parts["cls"]}


def short_run(cfg, templates, train, val, st: TrainSettings, seed: int) -> dict:
    t0 = time.perf_counter()
    history = []
    train_sctdn(cfg, templates, train, val, st, seed, lambda e, m: history.append(m))
    last = history[-1]
    return {k: last[k] for k in ("val_traj_l2_mm", "val_template_only_l2_mm", "val_cls_acc",
                                 "val_contact_within_1cm_rate")} | {
        "n_train_supports": len(train), "epochs": st.epochs, "minutes": (time.perf_counter() - t0) / 60}


@torch.no_grad()
def error_sources(model: Sctdn, val, views) -> dict:
    """Mean trajectory and ξ_0 errors (mm) over every validation (support, view): predicted
    family and contact (as deployed), true family given, true family and contact given."""
    model.eval()
    sums = {k: {"traj_mm": [], "xi0_mm": []} for k in ("predicted", "true_family", "true_family_and_contact")}
    for s in val:
        b = make_batch([(s, int(v)) for v in views])
        mm = b["scale"] * 1000
        for name, fam, con in (("predicted", None, None), ("true_family", b["family"], None),
                               ("true_family_and_contact", b["family"], b["contact"])):
            traj = model(b["xyz"], b["scale"], fam, con)["trajectory"]
            sums[name]["traj_mm"] += (traj_distance(traj, b["gt"], b["valid"]) * mm).tolist()
            xi0 = torch.linalg.norm(traj[:, None, 0] - b["gt"][:, :, 0], dim=-1)
            sums[name]["xi0_mm"] += (xi0.masked_fill(~b["valid"], float("inf")).min(-1).values * mm).tolist()
    return {k: {m: float(np.mean(v)) for m, v in d.items()} for k, d in sums.items()}


@torch.no_grad()
def contact_misses(model: Sctdn, val, views, tangents: dict) -> dict:
    """Per level (and ``all``): views that show the contact, those whose predicted contact
    (argmax affordance) is within :data:`CONTACT_OK_M`, the misses whose error lies mostly
    along the hanging arm (``tangents[support_id]``, unit), and the views within
    :data:`CONTACT_OK_M` across the arm (the error's component normal to it)."""
    model.eval()
    rows = {lv: np.zeros(4, int) for lv in (*LEVELS, "all")}
    for s in val:
        b = make_batch([(s, int(v)) for v in views])
        picked = model(b["xyz"], b["scale"])["affordance"].argmax(-1).tolist()
        t = tangents[s.support_id]
        for v, j in zip(views, picked):
            if not s.contact_visible[int(v)]:
                continue
            e = s.points[int(v)][j].astype(np.float64) - s.contact
            along, across = abs(e @ t), float(np.linalg.norm(e - (e @ t) * t))
            miss = np.linalg.norm(e) > CONTACT_OK_M
            for lv in (s.level, "all"):
                rows[lv] += [1, not miss, miss and along > across, across <= CONTACT_OK_M]
    return {lv: dict(zip(("visible", "within_1cm", "misses_along_arm", "within_1cm_across_arm"),
                         map(int, r))) for lv, r in rows.items() if r[0]}


#: Waypoints from ξ_0 that make the "hanging end" of an SKT in :func:`per_level`.
HANG_END = 10


def _nearest_gt_errors(traj: torch.Tensor, gt: torch.Tensor, valid: torch.Tensor) -> torch.Tensor:
    """``(B, T)`` waypoint distances of ``traj (B, T, 3)`` to its nearest (mean waypoint
    distance) ground-truth SKT of ``gt (B, G, T, 3)``."""
    d = torch.linalg.norm(traj[:, None] - gt, dim=-1)  # (B, G, T)
    nearest = d.mean(-1).masked_fill(~valid, float("inf")).argmin(-1)
    return d[torch.arange(len(d)), nearest]


@torch.no_grad()
def per_level(model: Sctdn, val, views, k: int) -> dict:
    """Per level (and ``all``) of the validation supports, every view in ``views``: mean
    trajectory error (mm) over the SKT and over its :data:`HANG_END` waypoints from ξ_0, the
    ξ_0 error, the same two trajectory errors with the true family and contact given,
    classifier accuracy and confusion (``confusion[true][predicted]``, ``k`` families), and
    the contact within :data:`CONTACT_OK_M` over the views that show it."""
    model.eval()
    rows: dict = {}
    for s in val:
        b = make_batch([(s, int(v)) for v in views])
        mm = (b["scale"] * 1000)[:, None]
        out = model(b["xyz"], b["scale"])
        forced = model(b["xyz"], b["scale"], b["family"], b["contact"])["trajectory"]
        err = _nearest_gt_errors(out["trajectory"], b["gt"], b["valid"]) * mm
        err_forced = _nearest_gt_errors(forced, b["gt"], b["valid"]) * mm
        picked = out["affordance"].argmax(-1).tolist()
        pred = out["logits"].argmax(-1).tolist()
        for i, v in enumerate(views):
            for lv in (s.level, "all"):
                r = rows.setdefault(lv, {"traj_mm": [], "hang_end_mm": [], "xi0_mm": [],
                                         "forced_traj_mm": [], "forced_hang_end_mm": [],
                                         "contact_ok": [], "confusion": np.zeros((k, k), int)})
                r["traj_mm"].append(float(err[i].mean()))
                r["hang_end_mm"].append(float(err[i, :HANG_END].mean()))
                r["xi0_mm"].append(float(err[i, 0]))
                r["forced_traj_mm"].append(float(err_forced[i].mean()))
                r["forced_hang_end_mm"].append(float(err_forced[i, :HANG_END].mean()))
                r["confusion"][s.family, pred[i]] += 1
                if s.contact_visible[int(v)]:
                    e = np.linalg.norm(s.points[int(v)][picked[i]].astype(np.float64) - s.contact)
                    r["contact_ok"].append(bool(e <= CONTACT_OK_M))
    out = {}
    for lv in (*LEVELS, "all"):
        if lv not in rows:
            continue
        r = rows[lv]
        c = r["confusion"]
        out[lv] = {m: float(np.mean(r[m])) for m in ("traj_mm", "hang_end_mm", "xi0_mm",
                                                      "forced_traj_mm", "forced_hang_end_mm")} | {
            "n_views": int(c.sum()), "cls_acc": float(np.trace(c) / c.sum()),
            "confusion": c.tolist(),
            "contact_within_1cm": float(np.mean(r["contact_ok"])) if r["contact_ok"] else None,
            "n_contact_visible": len(r["contact_ok"])}
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--params", default="params.yaml")
    ap.add_argument("--data-root", default="data")
    ap.add_argument("--out", default="reports/train")
    ap.add_argument("--epochs", type=int, default=10, help="epochs of each short run")
    ap.add_argument("--steps", type=int, default=300, help="steps of the one-batch overfit")
    args = ap.parse_args(argv)
    params = load_params(args.params)
    p, seed, root = params.train, params.common.seed, Path(args.data_root)
    tz = read_npz(root / "clustering" / "templates.npz", {"templates": ("float64", 3)})
    T, k = int(tz["T"]), int(tz["k"])
    supports = load_supports(root, T)
    train = sorted((s for s in supports if s.split == "train"), key=lambda s: s.support_id)
    val = [s for s in supports if s.split == "val"]
    cfg, st = from_params(p, k, T, supports[0].points.shape[1])
    st = dataclasses.replace(st, epochs=args.epochs)
    out: dict = {"params": args.params, "short_run_epochs": args.epochs}
    print("overfit one batch …", flush=True)
    out["overfit_one_batch"] = overfit_one_batch(cfg, tz["templates"], train, seed, args.steps)
    out["learning_curve"] = []
    for frac in (0.25, 0.5, 1.0):
        n = max(1, round(frac * len(train)))
        print(f"learning curve: {n} supports …", flush=True)
        out["learning_curve"].append(short_run(cfg, tz["templates"], train[:n], val, st, seed))
    print("contact term off …", flush=True)
    out["contact_weight_0"] = short_run(cfg, tz["templates"], train, val,
                                        dataclasses.replace(st, contact_weight=0.0), seed)
    out["contact_weight_committed"] = out["learning_curve"][-1] | {"contact_weight": p.contact_weight}
    model = SktPredictor.load(root / "train").model
    out["committed_model"] = {"train": evaluate(model, train, p.val_views),
                              "val": evaluate(model, val, p.val_views)}
    out["error_sources"] = error_sources(model, val, p.val_views)
    sup = read_table(root / "mesh_gen" / "supports.parquet", SUPPORTS).set_index("support_id")
    tangents = {sid: np.asarray(t, float) / np.linalg.norm(t) for sid, t in sup["hang_tangent"].items()}
    out["contact_misses"] = contact_misses(model, val, p.val_views, tangents)
    out["per_level"] = per_level(model, val, p.val_views, k)
    dest = Path(args.out)
    dest.mkdir(parents=True, exist_ok=True)
    (dest / "diagnostics.json").write_text(json.dumps(out, indent=2, sort_keys=True) + "\n")
    (dest / "diagnostics.md").write_text(_markdown(out))
    print(f"wrote {dest / 'diagnostics.md'}")
    return 0


def _f(x) -> str:
    return "–" if x is None else f"{x:.3f}"


def _markdown(d: dict) -> str:
    o = d["overfit_one_batch"]
    lines = ["# train diagnostics", "",
             "Written by `tools/train_diagnostics.py` (`make train-diagnostics`) on the committed "
             f"params and the artifacts of `make repro`; short runs of {d['short_run_epochs']} epochs.", "",
             f"**Overfit one batch** ({o['n_views']} views, {o['steps']} steps): trajectory error "
             f"{o['traj_first_mm']:.1f} → {o['traj_last_mm']:.2f} mm, classifier loss {o['cls_last']:.3f}.", "",
             "**Learning curve** (validation, last epoch):", "",
             "| training supports | SCTDN mm | template-only mm | cls acc | contact ≤ 1 cm | minutes |",
             "|---|---|---|---|---|---|"]
    for r in d["learning_curve"]:
        lines.append(f"| {r['n_train_supports']} | {r['val_traj_l2_mm']:.1f} | {r['val_template_only_l2_mm']:.1f} "
                     f"| {r['val_cls_acc']:.3f} | {_f(r['val_contact_within_1cm_rate'])} | {r['minutes']:.1f} |")
    lines += ["", "**Contact term** (all training supports, same short run):", "",
              "| contact_weight | SCTDN mm | template-only mm | cls acc | contact ≤ 1 cm |", "|---|---|---|---|---|"]
    for name, r in (("0 (paper loss)", d["contact_weight_0"]),
                    (str(d["contact_weight_committed"]["contact_weight"]), d["contact_weight_committed"])):
        lines.append(f"| {name} | {r['val_traj_l2_mm']:.1f} | {r['val_template_only_l2_mm']:.1f} "
                     f"| {r['val_cls_acc']:.3f} | {_f(r['val_contact_within_1cm_rate'])} |")
    lines += ["", "**Train vs val**, committed model (`data/train`), the same views of each support:", "",
              "| split | SCTDN mm | template-only mm | cls acc | contact ≤ 1 cm |", "|---|---|---|---|---|"]
    for split in ("train", "val"):
        r = d["committed_model"][split]
        lines.append(f"| {split} | {r['val_traj_l2_mm']:.1f} | {r['val_template_only_l2_mm']:.1f} "
                     f"| {r['val_cls_acc']:.3f} | {_f(r['val_contact_within_1cm_rate'])} |")
    e = d["error_sources"]
    lines += ["", "**What the errors come from**, committed model, validation views: the same model "
              "given the true family, then the true family and contact (teacher forcing at read-out):", "",
              "| family, contact | SCTDN mm | ξ_0 error mm |", "|---|---|---|"]
    for name, label in (("predicted", "predicted (as deployed)"), ("true_family", "true family"),
                        ("true_family_and_contact", "true family and contact")):
        lines.append(f"| {label} | {e[name]['traj_mm']:.1f} | {e[name]['xi0_mm']:.1f} |")
    lines += ["", "**Where the contact misses**, committed model, validation views that show the "
              "contact; a miss (> 1 cm) is *along the arm* when its component along the hanging arm "
              "at the hang (the generator's `hang_tangent`) exceeds the one across it:", "",
              "| level | views | within 1 cm | misses | of them along the arm | within 1 cm across the arm |",
              "|---|---|---|---|---|---|"]
    for lv, r in d["contact_misses"].items():
        n = r["visible"]
        lines.append(f"| {lv} | {n} | {r['within_1cm'] / n:.3f} | {n - r['within_1cm']} "
                     f"| {r['misses_along_arm']} | {r['within_1cm_across_arm'] / n:.3f} |")
    pl = d["per_level"]
    lines += ["", f"**Per level**, committed model, validation views, no teacher forcing unless said: "
              f"trajectory error over the SKT and over its {HANG_END} waypoints from ξ_0 (the hanging "
              "end, where a threading is decided), ξ_0 error, the classifier, the contact; the last two "
              "columns with the true family and contact given:", "",
              "| level | views | SKT mm | hanging end mm | ξ_0 mm | cls acc | contact ≤ 1 cm "
              "| SKT mm, true family + contact | hanging end mm, true family + contact |",
              "|---|---|---|---|---|---|---|---|---|"]
    for lv, r in pl.items():
        lines.append(f"| {lv} | {r['n_views']} | {r['traj_mm']:.1f} | {r['hang_end_mm']:.1f} "
                     f"| {r['xi0_mm']:.1f} | {r['cls_acc']:.3f} | {_f(r['contact_within_1cm'])} "
                     f"({r['n_contact_visible']} views) | {r['forced_traj_mm']:.1f} "
                     f"| {r['forced_hang_end_mm']:.1f} |")
    k = len(pl["all"]["confusion"])
    lines += ["", "**Classifier confusion per level** (validation views; row: true family, "
              "column: predicted):", ""]
    for lv, r in pl.items():
        if lv == "all":
            continue
        lines += [f"*{lv}*", "", "| true \\ predicted | " + " | ".join(map(str, range(k))) + " |",
                  "|---|" + "---|" * k]
        lines += [f"| {j} | " + " | ".join(map(str, row)) + " |" for j, row in enumerate(r["confusion"])]
        lines.append("")
    return "\n".join(lines).rstrip("\n") + "\n"


if __name__ == "__main__":
    sys.exit(main())
