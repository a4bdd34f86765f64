"""Training-seed spread of the learned methods (``make seeds``, after ``make repro``).

The committed pipeline trains SCTDN and the baselines with ``common.seed``. This run trains
them again with ``--seeds`` more training seeds (``common.seed + 1``, ``+ 2``, …) on the
same committed data and evaluates each seed's models with ``sim_eval`` on the same test
supports, views, objects and VAT-Mart latents (all drawn from ``common.seed``), so the spread
is the training seed's alone. Methods: ``template_only`` and ``sctdn`` (one SCTDN model),
``vatmart``, ``vatmart_mod``.

Deviation from "``common.seed`` sweeps via ``dvc exp run``": changing ``common.seed``
regenerates the whole dataset (other supports, other test set; ~35 min a seed here), which
mixes the data's variance into the model's. Here only the training seed moves.

Writes ``data/seed_sweep/seed_<s>/`` (models and sim_eval outputs, git-ignored scratch: an
interrupted run resumes from it; it is wiped when ``params.yaml`` or ``dvc.lock`` — the data
it was made from — differ from the stamp it was made under) and
``reports/seeds/{seeds.json, report.md}``: per method and level the success rate of each
seed, mean and min–max. Seed ``common.seed`` is read from ``reports/sim_eval/metrics.json``
(the committed run); it must be up to date (``dvc status``).
"""

import argparse
import hashlib
import json
import shutil
import sys
from pathlib import Path

import numpy as np
import yaml

from skt_lib.config import LEVELS, load_params
from skt_lib.io import write_text_atomic
from skt_lib.learning.data import load_training_set
from skt_lib.learning.predictor import SktPredictor
from skt_lib.learning.train import from_params, train_sctdn
from skt_lib.learning.train_baselines import train_vatmart, vatmart_config
from skt_lib.learning.vatmart import VatMartPredictor
from stages import sim_eval
from viz.report import Report

METHODS = ("template_only", "sctdn", "vatmart", "vatmart_mod")
KEYS = ("all", *LEVELS)


def train_models(params, root: Path, seed: int, out: Path) -> None:
    """SCTDN → ``out/train``, the two VAT-Mart models → ``out/train_baselines/<name>``."""
    p, pb = params.train, params.train_baselines
    data = load_training_set(root)
    train, val = data.train, data.val
    cfg, st = from_params(p, data.k, data.T, data.n_points)
    if not (out / "train" / "sctdn.pt").exists():
        model, _ = train_sctdn(cfg, data.templates, train, val, st, seed)
        SktPredictor(model).save(out / "train")
    for name in ("vatmart", "vatmart_mod"):
        if (out / "train_baselines" / name / "vatmart.pt").exists():
            continue
        vcfg = vatmart_config(name, cfg, pb)
        model, _ = train_vatmart(vcfg, train, val, st, seed, params.sim_eval.n_proposals)
        VatMartPredictor(model).save(out / "train_baselines" / name)


def overlay(root: Path, out: Path) -> Path:
    """A data root that is ``root`` except for ``train`` and ``train_baselines``, which are
    this seed's (symbolic links; nothing under ``root`` is written)."""
    view = out / "root"
    view.mkdir(parents=True, exist_ok=True)
    for entry in root.iterdir():
        if entry.name in ("train", "train_baselines", "seed_sweep") or entry.name.startswith("."):
            continue
        link = view / entry.name
        if not link.exists():
            link.symlink_to(entry.resolve())
    for name in ("train", "train_baselines"):
        if not (view / name).exists():
            (view / name).symlink_to((out / name).resolve())
    return view


def evaluate(params_path: Path, root: Path, out: Path) -> dict:
    """sim_eval with ``METHODS`` only and no recording; its metrics."""
    data = yaml.safe_load(params_path.read_text())
    data["sim_eval"]["methods"] = list(METHODS)
    data["sim_eval"]["n_record"] = 0
    params = out / "params.yaml"
    params.write_text(yaml.safe_dump(data, sort_keys=False))
    metrics = out / "reports" / "metrics.json"
    if not metrics.exists():
        code = sim_eval.main(["--params", str(params), "--data-root", str(overlay(root, out)),
                              "--data-dir", str(out / "sim_eval"), "--reports-dir",
                              str(out / "reports")])
        if code:
            raise SystemExit(code)
    return json.loads(metrics.read_text())


def inputs_key(params_path: Path, data_root: Path) -> str:
    """What a seed's scratch outputs were made from: ``params.yaml`` and the ``dvc.lock``
    beside ``data_root`` (the hashes of every stage's inputs and outputs)."""
    h = hashlib.sha256(params_path.read_bytes())
    lock = data_root.resolve().parent / "dvc.lock"
    h.update(lock.read_bytes() if lock.is_file() else b"")
    return h.hexdigest()


def fresh_scratch(out: Path, key: str) -> None:
    """Keep ``out`` (resume) only when its stamp is ``key``; else start it empty, stamped."""
    stamp = out / "inputs.sha256"
    if out.exists() and not (stamp.is_file() and stamp.read_text() == key):
        shutil.rmtree(out)
    out.mkdir(parents=True, exist_ok=True)
    stamp.write_text(key)


def spread(per_seed: dict[int, dict]) -> dict:
    """{method: {"success": {level: {"seeds": [...], "mean", "min", "max"}}, …}} (also
    ``success_single`` for the proposing methods)."""
    out = {}
    for m in METHODS:
        out[m] = {}
        for key in ("success", "success_single"):
            if key not in next(iter(per_seed.values()))[m]:
                continue
            out[m][key] = {}
            for lv in KEYS:
                vals = [per_seed[s][m][key][lv] for s in per_seed]
                vals = [v for v in vals if v is not None]
                out[m][key][lv] = {"seeds": vals, "mean": float(np.mean(vals)),
                                   "min": float(np.min(vals)), "max": float(np.max(vals))}
    return out


def write_report(reports: Path, per_seed: dict, table: dict) -> None:
    report = Report("seeds", reports)
    seeds = list(per_seed)
    report.text(f"Training seeds {seeds} (the first is the committed pipeline's "
                "`common.seed`); same data, test set, views and VAT-Mart latents for every seed: "
                "the spread below is the training seed's alone. Success % mean [min–max] over "
                "the seeds; `vatmart*` best-of-N as in Table I, 'first proposal' the honest "
                "single-sample rate. Reproduce: `make seeds` (tools/seed_sweep.py).")
    rows = []
    for m in METHODS:
        for key, label in (("success", m), ("success_single", f"{m}, first proposal")):
            if key in table[m]:
                rows.append([label, *(f"{100 * table[m][key][lv]['mean']:.1f} "
                                      f"[{100 * table[m][key][lv]['min']:.1f}–"
                                      f"{100 * table[m][key][lv]['max']:.1f}]" for lv in KEYS)])
    report.table(["method", "All", "Easy", "Normal", "Hard", "Very Hard"], rows)
    report.heading("Per seed (success %, all levels)")
    report.table(["seed", *METHODS],
                 [[s, *(f"{100 * per_seed[s][m]['success']['all']:.1f}" for m in METHODS)]
                  for s in seeds])
    report.write()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="tools/seed_sweep.py", description=__doc__.splitlines()[0])
    ap.add_argument("--params", default="params.yaml", type=Path)
    ap.add_argument("--data-root", default="data", type=Path)
    ap.add_argument("--reports", default="reports", type=Path)
    ap.add_argument("--seeds", type=int, default=3, help="seeds in all, the committed one included")
    args = ap.parse_args(argv)
    params = load_params(args.params)
    base = params.common.seed
    committed = json.loads((args.reports / "sim_eval" / "metrics.json").read_text())
    missing = [m for m in METHODS if m not in committed]
    if missing:
        print(f"ERROR: {args.reports / 'sim_eval' / 'metrics.json'}: no {missing}; run make "
              "repro with them in sim_eval.methods first", file=sys.stderr)
        return 2
    per_seed = {base: committed}
    for seed in range(base + 1, base + args.seeds):
        out = args.data_root / "seed_sweep" / f"seed_{seed}"
        print(f"seed {seed}: training → {out}", flush=True)
        fresh_scratch(out, inputs_key(args.params, args.data_root))
        train_models(params, args.data_root, seed, out)
        per_seed[seed] = evaluate(args.params, args.data_root, out)
    table = spread(per_seed)
    rep = args.reports / "seeds"
    rep.mkdir(parents=True, exist_ok=True)
    write_text_atomic(rep / "seeds.json",
                      json.dumps({"seeds": list(per_seed), "methods": table}, indent=2) + "\n")
    write_report(rep, per_seed, table)
    return 0


if __name__ == "__main__":
    sys.exit(main())
