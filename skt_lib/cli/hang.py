"""``skt hang``: one Franka trial of an object on a support along a method's SKT.

The support is rendered from one view (as ``sim_eval`` gives it to the methods), the method
predicts the SKT, and the trial runs with ``sim_eval``'s executor and strict predicate
(:func:`skt_lib.sim.execute.run_trial`). Prints the verdict and failure reason; ``--rrd``
writes the rollout (robot, object, support, SKT) to Rerun. A mesh file given for
``--support`` or ``--object`` is imported first, as ``skt import-support`` /
``skt import-object`` would (named after the file): into a temporary data root that links
the real one's folders, or into the real one with ``--keep``.
"""

import os
import tempfile
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from skt_lib.cli.common import load_predictor, progress
from skt_lib.config import load_params
from skt_lib.errors import InputError
from skt_lib.eval.methods import LEARNED, make_method
from skt_lib.eval.protocol import make_task, trial_settings
from skt_lib.items import USER, find_object, find_support, user_dir
from skt_lib.sim.execute import run_trial

METHODS = ("sctdn", "template_only", "oracle", "oracle_floating", "kpam")
MESH_SUFFIXES = {".obj", ".stl", ".ply", ".glb", ".gltf", ".off"}
EXAMPLE = """example:
  skt hang --support support_00003 --object object_mug_001 --method sctdn --rrd hang.rrd
  skt hang --support my_hook --object my_mug --method oracle   # imported with skt import-*
  skt hang --support hook.stl --object mug.obj --units mm      # imported on the fly"""


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
    ap.add_argument("--method", choices=METHODS, default="sctdn",
                    help="SKT method (default: sctdn)")
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
    skt = m.predict(support.cloud)
    task = make_task(method, support, obj, skt.positions, trial_settings(p, params.contact_sim),
                     record_every, fallbacks=skt.fallbacks[:p.setup_fallbacks])
    return {"task": task, **run_trial(task)}


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


def run(args) -> int:
    params = load_params(args.params)
    if args.keep or not (is_mesh(args.support) or is_mesh(args.object)):
        import_meshes(args, params, Path(args.data_root))
        return _run(args, params, Path(args.data_root))
    skip = {(k, Path(v).stem) for k, v in (("support", args.support), ("object", args.object))
            if is_mesh(v)}
    with tempfile.TemporaryDirectory(prefix="skt-hang-") as tmp:
        root = overlay(Path(args.data_root), Path(tmp), skip)
        import_meshes(args, params, root)
        return _run(args, params, root)


def _run(args, params, root: Path) -> int:
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
