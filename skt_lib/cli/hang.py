"""``skt hang``: one Franka trial of an object on a support along a method's SKT.

The support is rendered from one view (as ``sim_eval`` gives it to the methods), the method
predicts the SKT, and the trial runs with ``sim_eval``'s executor and strict predicate
(:func:`skt_lib.sim.execute.run_trial`). Prints the verdict and failure reason; ``--rrd``
writes the rollout (robot, object, support, SKT) to Rerun.
"""

import time
from pathlib import Path

import numpy as np

from skt_lib.cli.common import load_predictor, progress
from skt_lib.cli.items import find_object, find_support
from skt_lib.config import load_params
from skt_lib.errors import InputError
from skt_lib.eval.methods import LEARNED, make_method
from skt_lib.eval.protocol import make_task, trial_settings
from skt_lib.sim.execute import run_trial

METHODS = ("sctdn", "template_only", "oracle", "oracle_floating", "kpam")
EXAMPLE = """example:
  skt hang --support support_00003 --object object_mug_001 --method sctdn --rrd hang.rrd
  skt hang --support my_hook --object my_mug --method oracle   # imported with skt import-*"""


def add_parser(sub) -> None:
    ap = sub.add_parser("hang", help="hang an object on a support in simulation and record it",
                        description=__doc__.splitlines()[0], epilog=EXAMPLE)
    ap.add_argument("--support", required=True,
                    help="a mesh_gen support id or the name of an imported support")
    ap.add_argument("--object", required=True,
                    help="a mesh_gen object id or the name of an imported object")
    ap.add_argument("--method", choices=METHODS, default="sctdn", help="SKT method (default: sctdn)")
    ap.add_argument("--params", default="params.yaml", help="params file (default: params.yaml)")
    ap.add_argument("--data-root", default="data", help="pipeline artifacts (default: data)")
    ap.add_argument("--model", help="trained model folder (default: <data-root>/train)")
    ap.add_argument("--rrd", help="write the rollout to this Rerun recording")
    ap.set_defaults(run=run)


def hang(support, obj, method: str, params, model_dir: Path | None, record_every: int = 0) -> dict:
    """Predict with ``method`` on the support's view and run one trial; ``run_trial``'s result
    (``row`` of schema ``trials``, and a trace when ``record_every > 0``) plus the SKT."""
    p = params.sim_eval
    predictor = None
    if method in LEARNED:
        predictor = load_predictor(model_dir)
        if predictor.cfg.T != params.clustering.T:
            raise InputError(f"{model_dir}: model predicts T = {predictor.cfg.T}, "
                             f"clustering.T is {params.clustering.T}")
    m = make_method(method, predictor, support.gt, np.asarray(p.kpam_pre_hang_m, float),
                    p.kpam_lift_m)
    positions = m.predict(support.cloud).positions
    task = make_task(method, support, obj, positions, trial_settings(p, params.contact_sim),
                     record_every)
    return {"task": task, **run_trial(task)}


def run(args) -> int:
    params = load_params(args.params)
    root = Path(args.data_root)
    model = Path(args.model) if args.model else root / "train"
    with progress(3, "hang") as bar:
        support = find_support(args.support, root, params)
        obj = find_object(args.object, root, params)
        bar.update()
        t0 = time.perf_counter()
        every = params.sim_eval.record_every if args.rrd else 0
        out = hang(support, obj, args.method, params, model, every)
        bar.update()
        if args.rrd:
            from skt_lib.cli.rrd import log_hang

            log_hang(Path(args.rrd), out["task"], out, support, obj,
                     tuple(params.sim_eval.robot_base_m))
        bar.update()
    row = out["row"]
    verdict = "success" if row["success"] else f"failed: {row['failure_reason']}"
    detail = f" ({row['detail']})" if row["detail"] else ""
    print(f"{args.method} {support.support_id} × {obj.object_id}: {verdict}{detail}; "
          f"{row['n_executed']}/{row['n_commands']} commands, grasp {row['grasp'] or '–'}, "
          f"{time.perf_counter() - t0:.1f} s" + (f"; rollout in {args.rrd}" if args.rrd else ""))
    return 0
