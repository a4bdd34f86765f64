"""Validation in simulation (``make val-sim``, after ``make repro``): the learned methods hang
the *training* objects on the *validation* supports with ``sim_eval``'s executor, grasps,
physics and predicate, so that a choice about a method (a checkpoint, a setting, a model
trained otherwise) can be taken on hang rates without touching the test set.

Table I's trials pair test supports with test objects; here validation supports (their own
seeded view, drawn as ``sim_eval`` draws a test support's) meet the training objects. The
models are the pipeline's (``data/train``, ``data/train_baselines``) unless ``--model
NAME=DIR`` names another directory for one of them (e.g. a scratch SCTDN trained with other
settings). Writes a JSON (``--out``) with per method the success per level, its Wilson 95 %
interval and failure reasons, exact McNemar tests of the first method against every
other on the same (support, object) pairs, and every pair's outcome (``outcomes``:
``{method: {"<support_id>/<object_id>": bool}}``, to pair two runs). Nothing under the data
root or ``reports/`` changes.

The oracles (``--methods oracle oracle_floating``: each validation support's stored SKTs,
as in Table I) take part too, so that a choice about the executor itself (e.g.
``--robot-base``, where the Panda stands) is taken on the ground truth's validation hang
rate, not on the test set's.
"""

import argparse
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd

from skt_lib.config import LEVELS
from skt_lib.config.params_file import load_params
from skt_lib.eval.methods import FALLS_BACK_TO_STORED, MODEL_OF, PREDICTOR_OF, Proposals, \
    load_models, make_method
from skt_lib.eval.probe_check import load_probes
from skt_lib.eval.protocol import load_test_set, per_pair, predict_all, success_table, \
    trial_settings
from skt_lib.eval.rounds import run_rounds
from skt_lib.io import write_json_atomic
from skt_lib.learning.predictor import SktPredictor
from skt_lib.learning.sctdn import Sctdn
from skt_lib.seeding import item_rng
from skt_lib.sim.execute import REASONS, run_trial
from skt_lib.stats import paired_comparisons, success_ci95
from stages._common import run_items


def _model_override(text: str) -> tuple[str, Path]:
    name, sep, directory = text.partition("=")
    if not sep or name not in set(MODEL_OF.values()):
        raise argparse.ArgumentTypeError(f"expected NAME=DIR with NAME one of "
                                         f"{sorted(set(MODEL_OF.values()))}, got {text!r}")
    return name, Path(directory)


def with_readout(predictor: SktPredictor, **changes) -> SktPredictor:
    """``predictor``'s weights with other read-out settings of
    :class:`~skt_lib.learning.sctdn.SctdnConfig` (``hang_taper``: the deformation faded in
    over that many waypoints from the hang; ``check_families``: the cloud check's
    candidates)."""
    model = Sctdn(replace(predictor.cfg, **changes), predictor.model.templates)
    model.load_state_dict(predictor.model.state_dict())
    return SktPredictor(model)


def validation_set(root: Path, T: int, seed: int, p) -> tuple[list, list, list]:
    """(validation supports, training objects, validation supports without an SKT) under
    ``root``, with ``sim_eval``'s grasps (``p``: its params). Exits with status 2, saying
    why, where there is nothing to evaluate."""
    supports, objects, missing = load_test_set(
        root, T, seed, p.grasp_pitch_deg, p.grasp_rolls_deg, p.grasp_yaws_deg,
        support_split="val", object_split="train", grasp_sphere=p.grasp_sphere_directions)
    if not supports or not objects:
        print(f"ERROR: {root}: no validation supports with an SKT or no training objects",
              file=sys.stderr)
        raise SystemExit(2)
    return supports, objects, missing


def run_all(tasks: list, compute, label: str) -> list[dict]:
    """:func:`~skt_lib.sim.execute.run_trial` of every task on the stages' runner, in order;
    a crashed trial is an error here, not a failure."""
    results, _, crashes = run_items(run_trial, tasks, compute, label)
    if crashes:
        raise RuntimeError(f"{len(crashes)} trials crashed, first: {crashes[0][0].trial_id}: "
                           f"{crashes[0][1]}")
    return results


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="tools/val_sim.py", description=__doc__.splitlines()[0])
    ap.add_argument("--params", default="params.yaml", type=Path)
    ap.add_argument("--data-root", default="data", type=Path)
    ap.add_argument("--methods", nargs="+", default=["sctdn", "template_only"],
                    choices=[*FALLS_BACK_TO_STORED, *sorted(MODEL_OF)],
                    help="the first is compared with each other")
    ap.add_argument("--model", action="append", default=[], type=_model_override,
                    metavar="NAME=DIR", help="load model NAME (sctdn, vatmart, …) from DIR")
    ap.add_argument("--hang-taper", type=int, default=None, metavar="N",
                    help="run the SCTDN models with this hang taper instead of their own "
                         "(train.hang_taper_waypoints; the same weights)")
    ap.add_argument("--check-families", type=int, default=None, metavar="N",
                    help="run the SCTDN models with this many families in the cloud check "
                         "instead of their own (train.check_families; the same weights)")
    ap.add_argument("--setup-fallbacks", type=int, default=None, metavar="N",
                    help="let the set-up fall back on this many of the cloud check's other "
                         "candidates instead of sim_eval.setup_fallbacks")
    ap.add_argument("--robot-base", type=float, nargs=3, default=None, metavar=("X", "Y", "Z"),
                    help="stand the Panda's base here (world, m) instead of at "
                         "sim_eval.robot_base_m")
    ap.add_argument("--grasp-sphere", type=int, default=None, metavar="N",
                    help="try grasps from N sphere directions after the grid instead of "
                         "sim_eval.grasp_sphere_directions")
    ap.add_argument("--no-clear", action="store_true",
                    help="run skt_flow's samples as drawn, not moved clear of the cloud "
                         "(skt_lib/eval/clear_shift.py): what the move gains")
    ap.add_argument("--no-probes", action="store_true",
                    help="order skt_flow's samples by the cloud check alone, not by the "
                         "training objects carried along them (skt_lib/eval/probe_check.py)")
    ap.add_argument("--flow-samples", type=int, default=None, metavar="N",
                    help="skt_flow draws N samples for the training objects to order, not "
                         "sim_eval.flow_samples (at least sim_eval.n_proposals)")
    ap.add_argument("--flow-contacts", type=int, default=None, metavar="K",
                    help="skt_flow's samples from K contact hypotheses, not "
                         "sim_eval.flow_contacts (skt_lib/eval/contact_hypotheses.py; 1: the "
                         "affordance's argmax alone)")
    ap.add_argument("--out", default=Path("data/val_sim/val_sim.json"), type=Path)
    args = ap.parse_args(argv)
    params = load_params(args.params)
    p, T, seed = params.sim_eval, params.clustering.T, params.common.seed
    if args.robot_base is not None:
        p = p.model_copy(update={"robot_base_m": tuple(args.robot_base)})
    if args.grasp_sphere is not None:
        p = p.model_copy(update={"grasp_sphere_directions": args.grasp_sphere})
    if args.flow_contacts is not None:
        p = p.model_copy(update={"flow_contacts": args.flow_contacts})
    if args.flow_samples is not None:
        if args.flow_samples < p.n_proposals:
            ap.error(f"--flow-samples: at least sim_eval.n_proposals ({p.n_proposals}), got "
                     f"{args.flow_samples}")
        p = p.model_copy(update={"flow_samples": args.flow_samples})
    supports, objects, missing = validation_set(args.data_root, T, seed, p)
    models = load_models(args.data_root, args.methods, T)
    for name, directory in args.model:
        models[name] = PREDICTOR_OF[name].load(directory)
    readout = {k: v for k, v in (("hang_taper", args.hang_taper),
                                 ("check_families", args.check_families)) if v is not None}
    if readout:
        models = {name: with_readout(m, **readout) if isinstance(m, SktPredictor) else m
                  for name, m in models.items()}
    pre = np.asarray(p.kpam_pre_hang_m, float)
    probes = None if args.no_probes or "skt_flow" not in args.methods else \
        load_probes(args.data_root)

    def make(m: str, s):
        made = make_method(m, models.get(MODEL_OF.get(m)), s.gt, pre, p.kpam_lift_m,
                           rng=item_rng(seed, f"val_sim/{m}", s.support_id),
                           n_proposals=p.n_proposals, flow_contacts=p.flow_contacts,
                           probes=probes, flow_samples=p.flow_samples)
        if args.no_clear and isinstance(made, Proposals):
            made.clear = False
        return made

    positions, _, _, fallbacks = predict_all(
        {m: (lambda s, m=m: make(m, s)) for m in args.methods}, supports)
    n_fallbacks = p.setup_fallbacks if args.setup_fallbacks is None else args.setup_fallbacks
    fallbacks = {key: f[:n_fallbacks] for key, f in fallbacks.items()}

    rows, _ = run_rounds(args.methods, supports, objects, positions,
                         trial_settings(p, params.contact_sim),
                         lambda tasks, label: run_all(tasks, params.compute, label), fallbacks)
    pairs = per_pair(pd.DataFrame(rows))
    table, ci = success_table(pairs), success_ci95(pairs, LEVELS)
    out = {"supports": len(supports), "supports_without_skt": missing, "objects": len(objects),
           "models": {name: str(d) for name, d in args.model}, "hang_taper": args.hang_taper,
           "check_families": args.check_families, "setup_fallbacks": n_fallbacks,
           "skt_flow_moved_clear": not args.no_clear,
           "skt_flow_probes": probes is not None,
           "skt_flow_samples": p.flow_samples if probes is not None else p.n_proposals,
           "flow_contacts": p.flow_contacts,
           "robot_base_m": list(p.robot_base_m),
           "grasp_sphere_directions": p.grasp_sphere_directions,
           "methods": {m: {"success": table[m], "success_ci95": ci[m],
                           "failures_by_reason": {r: int((g["failure_reason"] == r).sum())
                                                  for r in REASONS}}
                       for m, g in pairs.groupby("method", sort=False)},
           "paired": paired_comparisons(pairs, args.methods[0]),
           "outcomes": {m: {f"{r.support_id}/{r.object_id}": bool(r.success)
                            for r in g.itertuples()}
                        for m, g in pairs.groupby("method", sort=False)}}
    write_json_atomic(args.out, out)
    for m, v in out["methods"].items():
        print(f"{m:>22}: " + "  ".join(f"{k} {100 * x:.1f}" for k, x in v["success"].items()
                                       if x is not None))
    for k, c in out["paired"].items():
        print(f"{k}: {c['n_a_only']} / {c['n_b_only']} discordant, p = {c['p_value']:.3g}")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
