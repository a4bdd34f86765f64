"""``skt hang``: one Franka trial of an object on a support along a method's SKT.

The support is rendered from one view (as ``sim_eval`` gives it to the methods), the method —
any of ``sim_eval``'s, built as ``sim_eval`` builds it
(:func:`skt_lib.eval.methods.method_for`) — predicts the SKT, and the trial runs with
``sim_eval``'s executor and strict predicate (:func:`skt_lib.sim.execute.run_trial`). A
proposing method (VAT-Mart) runs its first proposal, or with ``--proposals N`` up to its first
N in order until one hangs (``sim_eval``'s best-of-N). Prints the verdict and failure reason;
``--rrd`` writes the rollout (robot, object, support, SKT) of the last trial to Rerun. A mesh
file given for ``--support`` or ``--object`` is imported first, as ``skt import-support`` /
``skt import-object`` would (named after the file): into a temporary data root that links the
real one's folders, or into the real one with ``--keep``.
"""

import os
import tempfile
import time
from pathlib import Path
from types import SimpleNamespace

from skt_lib.cli.common import count_arg, progress
from skt_lib.config.params_file import load_params
from skt_lib.config.sim_eval import METHODS
from skt_lib.errors import InputError
from skt_lib.eval.methods import MODEL_OF, PRIVILEGED, PROPOSING, load_model, method_for, model_dir
from skt_lib.eval.probe_check import load_probes
from skt_lib.eval.protocol import make_task, reference_points, trial_settings
from skt_lib.items import USER, find_object, find_support, user_dir
from skt_lib.sim.execute import run_trial

MESH_SUFFIXES = {".obj", ".stl", ".ply", ".glb", ".gltf", ".off"}
#: The methods that run a trained model (``--model``), in ``sim_eval``'s order.
LEARNED = tuple(m for m in METHODS if m in MODEL_OF)
EXAMPLE = """example:
  skt hang --support support_00003 --object object_mug_001 --method sctdn --rrd hang.rrd
  skt hang --support my_hook --object my_mug --method oracle   # imported with skt import-*
  skt hang --support hook.stl --object mug.obj --units mm      # imported on the fly
  skt hang --support support_00003 --object object_mug_001 --method vatmart --proposals 10"""


def add_parser(sub) -> None:
    ap = sub.add_parser("hang", help="hang an object on a support in simulation and record it",
                        description=__doc__.splitlines()[0], epilog=EXAMPLE)
    ap.add_argument("--support", required=True,
                    help="a mesh_gen support id, an imported support's name, or a mesh file")
    ap.add_argument("--object", required=True,
                    help="a mesh_gen object id, an imported object's name, or a mesh file")
    ap.add_argument("--units", choices=("m", "mm"), default="m",
                    help="units of mesh files given for --support/--object (default: m)")
    ap.add_argument("--keep", action="store_true",
                    help="keep mesh files' imports in <data-root>/user/ (default: a temporary "
                         "folder)")
    ap.add_argument("--method", choices=METHODS, default="skt_flow", metavar="METHOD",
                    help="SKT method, any of sim_eval's (default: skt_flow, the best one-SKT "
                         "method on validation; its first proposal): learned, with a trained "
                         f"model — {', '.join(LEARNED)}; privileged, built from the support's "
                         f"ground-truth SKT — {', '.join(PRIVILEGED)}")
    ap.add_argument("--proposals", type=count_arg, metavar="N",
                    help=f"{' and '.join(PROPOSING)} only: run up to N of the method's "
                         "proposals in order until one hangs (sim_eval's best-of-N; default 1: "
                         "the first proposal alone)")
    ap.add_argument("--params", default="params.yaml", help="params file (default: params.yaml)")
    ap.add_argument("--data-root", default="data", help="pipeline artifacts (default: data)")
    ap.add_argument("--model", help="trained model folder of a learned method (default: "
                                    "<data-root>/train for sctdn and template_only, "
                                    "<data-root>/train_baselines/<method> for the others)")
    ap.add_argument("--rrd", help="write the rollout to this Rerun recording")
    ap.set_defaults(run=run)


def load_method_model(method: str, model: Path | None, root: Path, T: int):
    """The trained model ``method`` runs (None for a method without one), from ``model`` or
    its place under ``root``; :class:`InputError` naming the folder if there is none."""
    if method not in MODEL_OF:
        return None
    d = model or model_dir(root, method)
    if not d.is_dir():
        stage = "train" if MODEL_OF[method] == "sctdn" else "train_baselines"
        extra = "" if stage == "train" else f", with {MODEL_OF[method]} in train_baselines.models"
        raise InputError(f"{d}: no such model folder: --method {method} needs the trained "
                         f"{MODEL_OF[method]} model (`dvc repro {stage}`{extra}, or --model)")
    return load_model(method, d, T)


def hang(support, obj, method: str, params, model=None, record_every: int = 0,
         proposals: int = 1, omni_points=None, probes=None) -> dict:
    """Predict with ``method`` on the support's view and run its trial: ``run_trial``'s result
    (``row`` of schema ``trials``, and a trace when ``record_every > 0``) of the last trial run,
    with its ``task``, ``method`` (the built method; omnihang's plan in ``.last``) and
    ``tried`` (trials run). A proposing method runs up to ``proposals`` of its proposals in
    order, stopping at the first that hangs, as ``sim_eval``'s rounds do; ``model``:
    :func:`load_method_model`'s; ``omni_points``: the reference object's samples (omnihang);
    ``probes``: the training objects skt_flow orders its samples by
    (:func:`~skt_lib.eval.probe_check.load_probes`)."""
    p = params.sim_eval
    proposing = method in PROPOSING
    m = method_for(method, support.support_id, support.gt, params,
                   {MODEL_OF[method]: model} if model is not None else {}, omni_points,
                   max(proposals, p.n_proposals) if proposing else None, probes)
    skts = m.propose(support.cloud) if proposing else [m.predict(support.cloud)]
    # sim_eval's fallbacks (protocol.predict_all): only for a method with one SKT
    fallbacks = () if len(skts) > 1 else skts[0].fallbacks[:p.setup_fallbacks]
    settings = trial_settings(p, params.contact_sim)
    for i, skt in enumerate(skts[:proposals]):
        task = make_task(method, support, obj, skt.positions, settings, record_every,
                         proposal=i, fallbacks=fallbacks if i == 0 else ())
        out = run_trial(task)
        if out["row"]["success"]:
            break
    return {"task": task, "method": m, "tried": i + 1, **out}


def is_mesh(value: str) -> bool:
    return Path(value).suffix.lower() in MESH_SUFFIXES and Path(value).is_file()


def overlay(root: Path, tmp: Path, skip: set[tuple[str, str]]) -> Path:
    """A data root in ``tmp`` whose folders link ``root``'s, imports included, except the
    ``(kind, name)`` imports in ``skip``: what is imported into it stays out of ``root``."""
    out = tmp / "data"
    out.mkdir()
    for entry in root.iterdir() if root.is_dir() else ():
        if entry.name != USER:
            os.symlink(entry.resolve(), out / entry.name)
    for kind in ("support", "object"):
        mine = user_dir(out, kind, "x").parent
        mine.mkdir(parents=True)
        theirs = user_dir(root, kind, "x").parent
        for entry in theirs.iterdir() if theirs.is_dir() else ():
            if (kind, entry.name) not in skip:
                os.symlink(entry.resolve(), mine / entry.name)
    return out


def import_meshes(args, params, root: Path) -> None:
    """Import the mesh files among ``--support``/``--object`` into ``root``; the arguments
    become their names."""
    from skt_lib.cli import import_mesh, import_support

    for kind, do_import in (("support", import_support.import_support),
                            ("object", import_mesh.import_object)):
        path = getattr(args, kind)
        if not is_mesh(path):
            continue
        name, _ = import_mesh.new_import(kind, path, None, root)
        ns = SimpleNamespace(mesh=path, name=name, units=args.units, data_root=root, mount=None,
                             out_axis=None, arm=None, aperture_point=None, aperture_axis=None)
        with progress(5, f"import {kind}") as bar:
            do_import(ns, params, bar)
        setattr(args, kind, name)


def check_args(args) -> None:
    """Options that do not go with ``--method``: one ``InputError`` before any work."""
    if args.proposals is not None and args.method not in PROPOSING:
        raise InputError(f"--proposals goes with a proposing method ({', '.join(PROPOSING)}), "
                         f"not --method {args.method}")
    if args.model and args.method not in MODEL_OF:
        raise InputError(f"--model goes with a learned method ({', '.join(LEARNED)}): "
                         f"--method {args.method} runs no trained model")


def run(args) -> int:
    params = load_params(args.params)
    check_args(args)
    # the model before any import: a missing model leaves nothing behind
    model = load_method_model(args.method, Path(args.model) if args.model else None,
                              Path(args.data_root), params.clustering.T)
    if args.keep or not (is_mesh(args.support) or is_mesh(args.object)):
        import_meshes(args, params, Path(args.data_root))
        return _run(args, params, Path(args.data_root), model)
    skip = {(k, Path(v).stem) for k, v in (("support", args.support), ("object", args.object))
            if is_mesh(v)}
    with tempfile.TemporaryDirectory(prefix="skt-hang-") as tmp:
        root = overlay(Path(args.data_root), Path(tmp), skip)
        import_meshes(args, params, root)
        return _run(args, params, root, model)


def _run(args, params, root: Path, model) -> int:
    privileged = args.method in PRIVILEGED
    gt_for = (f"--method {args.method} is privileged (built from the ground truth) and needs "
              f"one; the learned methods ({', '.join(LEARNED)}) do not") if privileged else None
    n = args.proposals or 1
    with progress(3, "hang") as bar:
        support = find_support(args.support, root, params, gt_for=gt_for)
        obj = find_object(args.object, root, params)
        omni = reference_points(root) if args.method == "omnihang" else None
        probes = load_probes(root) if args.method == "skt_flow" else None
        bar.update()
        t0 = time.perf_counter()
        every = params.sim_eval.record_every if args.rrd else 0
        out = hang(support, obj, args.method, params, model, every, n, omni, probes)
        bar.update()
        if args.rrd:
            from skt_lib.cli.rrd import log_hang

            log_hang(Path(args.rrd), out["task"], out, support, obj,
                     tuple(params.sim_eval.robot_base_m))
        bar.update()
    row = out["row"]
    verdict = "success" if row["success"] else f"failed: {row['failure_reason']}"
    detail = f" ({row['detail']})" if row["detail"] else ""
    notes = ""
    if args.method in PROPOSING:
        notes += f"; proposal {out['tried']} of {n}" + (" (none hung)" if not row["success"]
                                                         and n > 1 else "")
    if args.method == "omnihang":
        plan = out["method"].last
        notes += (f"; planned in {plan.seconds:.1f} s" if plan.solved else
                  f"; no plan in {plan.n_checks} checks: the straight approach")
    print(f"{args.method} {support.support_id} × {obj.object_id}: {verdict}{detail}{notes}; "
          f"{row['n_executed']}/{row['n_commands']} commands, grasp {row['grasp'] or '–'}, "
          f"{time.perf_counter() - t0:.1f} s" + (f"; rollout in {args.rrd}" if args.rrd else ""))
    return 0
