"""Training-seed spread of the learned methods (``make seeds``, after ``make repro``).

The committed pipeline trains SCTDN and the baselines with ``common.seed``. This run trains
them again with ``--seeds`` more training seeds (``common.seed + 1``, ``+ 2``, …) on the
same committed data and evaluates each seed's models with ``sim_eval`` on the same test
supports, views, objects and VAT-Mart latents (all drawn from ``common.seed``), so the spread
is the training seed's alone. Methods: :data:`skt_lib.eval.seeds.SEEDED` that
``sim_eval.methods`` runs (``template_only`` and ``sctdn`` share one SCTDN model).

Deviation from "``common.seed`` sweeps via ``dvc exp run``": changing ``common.seed``
regenerates the whole dataset (other supports, other test set; ~35 min a seed here), which
mixes the data's variance into the model's. Here only the training seed moves.

Writes ``data/seed_sweep/seed_<s>/`` (models and sim_eval outputs, git-ignored scratch: an
interrupted run resumes from it. Two stamps say what it was made from: ``models.sha256``
(:func:`skt_lib.eval.seeds.models_key`: training's data, code and params) and
``inputs.sha256`` (:func:`skt_lib.eval.seeds.inputs_key`: everything the trials' outcomes
depend on). When the first differs the scratch is wiped; when only the second does, the
seed's models are kept and only its ``sim_eval`` runs again) and
``reports/seeds/seed_runs.json`` (every extra seed's per-pair outcomes with
:func:`skt_lib.eval.seeds.inputs_key`; a ``sim_eval`` dependency).
``make seeds`` then reruns ``sim_eval``, which merges the seeds into Table I and
``reports/sim_eval/metrics.json`` (``seeds.<method>.success_mean`` …). The pipeline must be
up to date (``dvc status``) when this runs: the key is read from ``dvc.lock``.
"""

import argparse
import shutil
import sys
from pathlib import Path

import pandas as pd
import yaml

from skt_lib.config.params_file import load_params
from skt_lib.eval.methods import MODEL_OF
from skt_lib.eval.protocol import per_pair
from skt_lib.eval.seeds import SEEDED, inputs_key, models_key, runs_document
from skt_lib.io import read_table, write_json_atomic
from skt_lib.learning.data import load_training_set
from skt_lib.learning.pointnet2 import geometry_memo
from skt_lib.learning.predictor import SktPredictor
from skt_lib.learning.train import from_params, train_sctdn
from skt_lib.learning.train_baselines import train_baseline
from skt_lib.schemas import TRIALS
from stages import sim_eval


#: A seed scratch's stamps (module docstring) and what its evaluation wrote.
MODELS_STAMP, OUTCOMES_STAMP = "models.sha256", "inputs.sha256"
EVALUATED = ("sim_eval", "reports", "params.yaml")


def train_models(params, root: Path, seed: int, out: Path, methods) -> None:
    """The models ``methods`` run (:data:`~skt_lib.eval.methods.MODEL_OF`), trained with
    ``seed``: SCTDN → ``out/train``, the baselines → ``out/train_baselines/<name>``; a model
    already there is kept (resume)."""
    p, pb = params.train, params.train_baselines
    needed = {MODEL_OF[m] for m in methods}
    sets: dict = {}  # the views a model learns from (train_baselines.views), loaded once

    def views(name: str):
        kind = pb.views.get(name, "clean")
        if kind not in sets:
            sets[kind] = load_training_set(root, kind)
        return sets[kind]

    data = views("sctdn")
    cfg, st = from_params(p, data.k, data.T, data.n_points)
    with geometry_memo():
        if "sctdn" in needed and not (out / "train" / "sctdn.pt").exists():
            model, _ = train_sctdn(cfg, data.templates, data.train, data.val, st, seed)
            SktPredictor(model).save(out / "train")
        for name in pb.models:
            d = out / "train_baselines" / name
            if name in needed and not any((d / f"{kind}.json").exists()
                                          for kind in ("sctdn", "vatmart", "skt_flow")):
                data = views(name)
                predictor, _ = train_baseline(name, cfg, data.templates, data.train, data.val,
                                              st, seed, params.sim_eval.n_proposals, pb)
                predictor.save(d)


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


def evaluate(params_path: Path, root: Path, out: Path, methods) -> pd.DataFrame:
    """sim_eval with ``methods`` only and no recording; its per-pair outcomes."""
    data = yaml.safe_load(params_path.read_text())
    data["sim_eval"]["methods"] = list(methods)
    data["sim_eval"]["n_record"] = 0
    params = out / "params.yaml"
    params.write_text(yaml.safe_dump(data, sort_keys=False))
    trials = out / "sim_eval" / "trials.parquet"
    if not (out / "reports" / "metrics.json").exists():
        code = sim_eval.main(["--params", str(params), "--data-root", str(overlay(root, out)),
                              "--data-dir", str(out / "sim_eval"), "--reports-dir",
                              str(out / "reports")])
        if code:
            raise SystemExit(code)
    return per_pair(read_table(trials, TRIALS))


def fresh_scratch(out: Path, models: str, outcomes: str) -> None:
    """Keep ``out`` (resume) only when its stamps are ``models`` and ``outcomes``; keep its
    models alone when only ``outcomes`` differs; else start it empty. Stamps it."""
    def stamped(name: str, key: str) -> bool:
        return (out / name).is_file() and (out / name).read_text() == key

    if out.exists() and not stamped(MODELS_STAMP, models):
        shutil.rmtree(out)
    elif out.exists() and not stamped(OUTCOMES_STAMP, outcomes):
        for name in EVALUATED:
            path = out / name
            if path.is_dir():
                shutil.rmtree(path)
            elif path.exists():
                path.unlink()
    out.mkdir(parents=True, exist_ok=True)
    (out / MODELS_STAMP).write_text(models)
    (out / OUTCOMES_STAMP).write_text(outcomes)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="tools/seed_sweep.py", description=__doc__.splitlines()[0])
    ap.add_argument("--params", default="params.yaml", type=Path)
    ap.add_argument("--data-root", default="data", type=Path)
    ap.add_argument("--reports", default="reports", type=Path)
    ap.add_argument("--seeds", type=int, default=3, help="seeds in all, the committed one included")
    ap.add_argument("--scratch", type=Path, default=None,
                    help="models and sim_eval outputs per seed (default: DATA_ROOT/seed_sweep)")
    args = ap.parse_args(argv)
    if args.seeds < 2:
        ap.error(f"--seeds: at least 2 (the committed one and one more), got {args.seeds}")
    params = load_params(args.params)
    methods = [m for m in params.sim_eval.methods if m in SEEDED]
    if not methods:
        print(f"ERROR: {args.params}: sim_eval.methods runs none of {list(SEEDED)}",
              file=sys.stderr)
        return 2
    repo = args.params.resolve().parent
    key, models = inputs_key(repo), models_key(repo)
    base = params.common.seed
    pairs = {}
    for seed in range(base + 1, base + args.seeds):
        out = (args.scratch or args.data_root / "seed_sweep") / f"seed_{seed}"
        print(f"seed {seed}: {methods} → {out}", flush=True)
        fresh_scratch(out, models, key)
        train_models(params, args.data_root, seed, out, methods)
        pairs[seed] = evaluate(args.params, args.data_root, out, methods)
    path = args.reports / "seeds" / "seed_runs.json"
    write_json_atomic(path, runs_document(key, pairs))
    print(f"wrote {path}; `dvc repro sim_eval` merges it into Table I", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
