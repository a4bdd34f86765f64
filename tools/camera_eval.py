"""From a real depth camera (``make camera``, after ``make repro``; ``make seeds`` for the
default predictor's extra seeds): every learned method of Table I on the views a depth camera
would give — the wall in view, the sensor model of :mod:`skt_lib.perception.sensor` at
severities 0 (perfect) to 4 — against the true camera pose.

Each support of the split gets ``--views`` camera poses drawn from ``render_views``' ring
(seeded), each paired with one object (every object in turn; the same one for a view at
every severity, in every mode and for every method). Per view and severity, one cloud, made
ready for the models (support frame, cleaned, sampled to their N points: what ``skt predict``
does before its network) in each mode of :data:`MODES`:

- ``true``: moved by the true camera pose, the wall cut 4 mm in front of the true plane —
  the SKT "predicted from the true frame";
- ``assumed``: moved by the pose a user would assume (the sensor model's pose error: 1 cm
  and 2° at severity 1), the wall cut the same way, as ``skt predict --frame`` would be fed;
- ``up`` / ``level``: ``skt predict --camera`` with ``--up`` (the true gravity in the camera
  frame, as an IMU gives it) or ``--level``; the estimated frame's error against the truth
  is recorded at every severity of ``--severities``.

Every method (``--methods``, default every learned one) runs on the ``true`` and ``up``
clouds at each of ``--hang-severities``; the default predictor (``skt predict``'s model) also
on ``assumed`` and, at the headline severity, ``level``; its extra training seeds (``make
seeds``' models, when current) on the same clouds as it. A method predicts as in ``sim_eval``
(:func:`skt_lib.eval.methods.method_for`: the same latents per support), its SKTs are mapped
from the frame they were predicted in to the true one (what a robot given that frame
executes) and run by ``sim_eval``'s executor (Panda, grasps, physics, success predicate): a
proposing method's first proposal is its one-SKT row (``<method>@1``), the next ones run
where the earlier failed (its best-of-N row, ``<method>``), as in Table I.

Writes ``metrics.json``, ``report.md``, ``frame_errors.png`` and ``outcomes.json`` (every
trial's verdict by row, ``severity/mode`` and ``support/view/object``) to ``--reports-dir``
(default ``reports/camera``); nothing under the data root changes.
"""

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import torch
from tqdm import tqdm

from skt_lib.cli.predict import DEFAULT_MODEL, camera_cloud, model_cloud
from skt_lib.config.params_file import load_params
from skt_lib.errors import DataError, InputError
from skt_lib.eval.methods import LEARNED, PROPOSING, load_models, method_for, model_dir
from skt_lib.eval.probe_check import load_probes
from skt_lib.eval.protocol import SINGLE, load_test_set, make_task, trial_settings
from skt_lib.eval.seeds import models_key
from skt_lib.geometry.export import read_obj
from skt_lib.geometry.se3 import invert, transform_points
from skt_lib.io import write_json_atomic
from skt_lib.perception.sensor import CameraScene, Intrinsics, SensorModel, camera_view
from skt_lib.perception.views import support_cameras
from skt_lib.perception.wall_frame import WallSettings
from skt_lib.seeding import item_rng
from skt_lib.sim.execute import run_trial
from stages._common import run_items
from viz.report import write_metrics

#: Acceptance of the frame estimate (issue: within 5 mm and 2°).
FRAME_TOL_MM, FRAME_TOL_DEG = 5.0, 2.0
#: How a view becomes the support-frame cloud the model sees: the wall cut at the true plane
#: after the true (or the assumed) transform; ``skt predict --camera --up``; ``--level``.
MODES = {"true": "true frame", "assumed": "`--frame` off by the pose error",
         "up": "`--camera --up`", "level": "`--camera --level`"}
#: The modes every method runs in; the default predictor runs in all of :data:`MODES`.
EVERY_METHOD_MODES = ("true", "up")
#: --split: (support split, object split); validation pairs the training objects, as val_sim.
SPLITS = {"test": ("test", "test"), "val": ("val", "train")}
#: The sensor model's severity where the frame and the hang are judged; --level runs there.
HEADLINE = 1.0
#: ``skt predict``'s default model, as a method of Table I.
DEFAULT_METHOD = Path(DEFAULT_MODEL).name
#: Where ``make seeds`` keeps each extra seed's models (``seed_<s>/``, stamped), and how an
#: extra seed's row is labelled (``skt_flow@1 seed 20261124``).
SEED_SWEEP, SEED_SEP = "seed_sweep", " seed "


def frame_error(est: np.ndarray, true: np.ndarray) -> tuple[float, float]:
    """(translation mm, rotation °) of ``est @ inv(true)``: where the true support frame
    lands in the estimated one."""
    e = est @ invert(true)
    angle = np.degrees(np.arccos(np.clip((np.trace(e[:3, :3]) - 1) / 2, -1.0, 1.0)))
    return 1000 * float(np.linalg.norm(e[:3, 3])), float(angle)


def hang_modes(label: str, severity: float) -> list[str]:
    """The modes the row ``label``'s SKTs are hung from at ``severity``: every mode for the
    default predictor (its committed model), :data:`EVERY_METHOD_MODES` for the others."""
    if label != DEFAULT_METHOD:
        return list(EVERY_METHOD_MODES)
    return [m for m in MODES if m != "level" or severity == HEADLINE]


def evaluate_views(args, params, cfg) -> list[dict]:
    """Per view (support, object, camera) and severity: the frame error and the model-ready
    cloud (support frame as predicted in, the frame it was predicted in) of every mode, or
    why it was refused. ``cfg``: the models' (one ``n_points`` and ``centres`` for all)."""
    p, seed = params.render_views, params.common.seed
    supports, objects, _ = load_test_set(args.data_root, params.clustering.T, seed,
                                         params.sim_eval.grasp_pitch_deg,
                                         params.sim_eval.grasp_rolls_deg,
                                         params.sim_eval.grasp_yaws_deg, *SPLITS[args.split],
                                         grasp_sphere=params.sim_eval.grasp_sphere_directions)
    if not supports or not objects:
        raise DataError(f"{args.data_root}: no {args.split} supports with a ground-truth SKT "
                        "or no objects to hang")
    k = Intrinsics(p.width, p.height, p.fov_deg)
    views = []
    for s in tqdm(supports, desc="views", unit="support", dynamic_ncols=True):
        (mesh,) = read_obj(s.mesh)
        scene, cams = CameraScene(mesh), support_cameras(mesh, p)
        for v in sorted(item_rng(seed, "camera_eval", s.support_id)
                        .choice(len(cams), args.views, replace=False)):
            pose = cams[v].pose()
            for sev in args.severities:
                o = objects[len(views) // len(args.severities) % len(objects)]
                rng = item_rng(seed, "camera_eval", f"{s.support_id}/{v}/{sev:g}")
                cam = camera_view(scene, pose, k, SensorModel().at(sev), rng)
                hung = sev in args.hang_severities
                modes = hang_modes(DEFAULT_METHOD, sev) if hung else ["up"]
                views.append({"support": s, "object": o, "view": int(v), "severity": sev,
                              "pose": pose, "hung": hung,
                              **_ready_modes(cfg, cam, modes, f"{s.support_id} view {v}")})
    return views


def _ready_modes(cfg, cam, modes, name: str) -> dict:
    """One camera view made ready for the models in each of ``modes``: the clouds and the
    frames they are in, the refusals, and for ``--camera`` the frame errors, seconds (frame
    and cleaning) and whether ``skt predict`` would warn."""
    out = {"ready": {}, "refused": {}, "err": {}, "seconds": {}, "warned": {}}
    for mode in modes:
        t0 = time.perf_counter()
        try:
            if mode in ("true", "assumed"):  # moved by that pose, wall cut 4 mm off its plane
                frame = cam.pose if mode == "true" else cam.assumed
                cloud = transform_points(frame, cam.points)
                ready = model_cloud(cfg, cloud[cloud[:, 0] > WallSettings.off_wall_m], name=name)
                out["ready"][mode] = (ready.points, frame)
                continue
            up = cam.pose[:3, :3].T @ np.array([0.0, 0.0, 1.0]) if mode == "up" else None
            ready = camera_cloud(cfg, cam.points, up, name=name)
        except InputError as err:
            out["refused"][mode] = str(err)
            continue
        out["seconds"][mode] = time.perf_counter() - t0
        out["err"][mode] = frame_error(ready.camera_to_support, cam.pose)
        out["warned"][mode] = bool(ready.warnings)  # what `skt predict` prints to its user
        out["ready"][mode] = (ready.points, ready.camera_to_support)
    return out


def seed_models(root: Path, repo: Path, method: str) -> dict[str, Path]:
    """``{"<s>": model folder}`` of ``method`` for every extra training seed ``make
    seeds`` left under ``root/seed_sweep`` whose models are current (stamped with today's
    :func:`~skt_lib.eval.seeds.models_key`); stale ones are named on stderr and left out."""
    out, key = {}, models_key(repo)
    for d in sorted((root / SEED_SWEEP).glob("seed_*")):
        stamp = d / "models.sha256"
        folder = model_dir(d, method)
        if not folder.is_dir():
            continue
        if not stamp.is_file() or stamp.read_text() != key:
            print(f"camera_eval: {d} is stale (its models are not of the committed data and "
                  "code); run make seeds", file=sys.stderr)
            continue
        out[d.name.removeprefix("seed_")] = folder
    return out


def predict_views(views, params, models: dict, n_fb: int, probes=None) -> list[dict]:
    """One case per (row's model, view, mode): ``{"label", "method", "view_index", "mode",
    "proposals": [positions (T, 3) in the true support frame, …], "fallbacks"}``. ``models``:
    ``{label: (method, load_models' dict)}``; ``probes``: the training objects skt_flow orders
    its samples by (:func:`~skt_lib.eval.probe_check.load_probes`)."""
    cases = []
    for label, (method, loaded) in models.items():
        for i, v in enumerate(tqdm(views, desc=f"predict {label}", unit="view",
                                   dynamic_ncols=True)):
            if not v["hung"]:
                continue
            s = v["support"]
            for mode in hang_modes(label, v["severity"]):
                if mode not in v["ready"]:
                    continue
                cloud, est = v["ready"][mode]
                made = method_for(method, s.support_id, None, params, loaded, probes=probes)
                skts = made.propose(cloud) if hasattr(made, "propose") else [made.predict(cloud)]
                to_true = v["pose"] @ invert(est)  # what a robot given that frame executes
                fallbacks = () if len(skts) > 1 else skts[0].fallbacks[:n_fb]  # as sim_eval
                cases.append({
                    "label": label, "method": method, "view_index": i, "mode": mode,
                    "proposals": [transform_points(to_true, k.positions)  # a seed: @1 only
                                  for k in (skts[:1] if SEED_SEP in label else skts)],
                    "fallbacks": tuple(transform_points(to_true, f) for f in fallbacks)})
    return cases


def run_hangs(views, cases, params) -> pd.DataFrame:
    """Each case's first SKT, then round by round a proposing method's next proposal where
    none of its earlier ones hung (Table I's best of N); a refused view fails every row that
    would have hung from it. One row per (row label, view, mode): ``success`` (first SKT),
    ``success_any`` (any proposal), the first SKT's ``failure_reason``."""
    settings = trial_settings(params.sim_eval, params.contact_sim)
    first, anyone = {}, {}
    todo, r = list(range(len(cases))), 0
    while todo:
        tasks = []
        for c in todo:
            case, v = cases[c], views[cases[c]["view_index"]]
            tasks.append(make_task(case["method"], v["support"], v["object"],
                                   case["proposals"][r], settings, proposal=r,
                                   fallbacks=case["fallbacks"] if r == 0 else ()))
        results, _, crashes = run_items(run_trial, tasks, params.compute,
                                        "trials" if r == 0 else f"proposal {r + 1}")
        if crashes:
            raise RuntimeError(f"{len(crashes)} trials crashed, first: {crashes[0][0].trial_id}")
        for c, res in zip(todo, results):
            if r == 0:
                first[c] = res["row"]
            anyone[c] = res["row"]["success"]
        r += 1
        todo = [c for c in todo if not anyone[c] and len(cases[c]["proposals"]) > r]
    rows = []
    for c, case in enumerate(cases):
        v = views[case["view_index"]]
        rows.append(_row(case["label"], case["method"], v, case["mode"],
                         first[c]["success"], anyone[c], first[c]["failure_reason"]))
    labels = {case["label"]: case["method"] for case in cases}
    for v in views:
        if v["hung"]:
            rows += [_row(label, method, v, mode, False, False, "refused")
                     for label, method in labels.items() for mode in v["refused"]
                     if mode in hang_modes(label, v["severity"])]
    return pd.DataFrame(rows)


def _row(label, method, v, mode, success, success_any, reason) -> dict:
    s = v["support"]
    return {"label": label, "method": method, "support_id": s.support_id,
            "difficulty": s.difficulty, "object_id": v["object"].object_id, "view": v["view"],
            "severity": v["severity"], "mode": mode, "success": bool(success),
            "success_any": bool(success_any), "failure_reason": reason}


def row_tables(trials: pd.DataFrame) -> dict[str, pd.DataFrame]:
    """Table I's rows: a proposing method's one-SKT row ``<label>@1`` (its first proposal)
    and best-of-N row ``<label>`` (any proposal); any other method's row ``<label>``.
    Columns as ``run_hangs``' with ``success`` the row's verdict."""
    out = {}
    for label, g in trials.groupby("label", sort=False):
        if g["method"].iloc[0] not in PROPOSING:
            out[label] = g
            continue
        base, sep, seed = label.partition(SEED_SEP)
        out[f"{base}{SINGLE}{sep}{seed}"] = g
        if not sep:  # no best-of-N row for an extra seed: it runs its first proposal only
            out[label] = g.assign(success=g["success_any"])
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="tools/camera_eval.py", description=__doc__.splitlines()[0])
    ap.add_argument("--params", default="params.yaml", type=Path)
    ap.add_argument("--data-root", default="data", type=Path)
    ap.add_argument("--reports-dir", default="reports/camera", type=Path)
    ap.add_argument("--views", type=int, default=5, help="views per test support (default 5)")
    ap.add_argument("--severities", type=float, nargs="+", default=[0.0, 1.0, 2.0, 3.0, 4.0],
                    help="sensor model severities where the frame is judged (default 0 1 2 3 "
                         f"4; {HEADLINE:g} is the headline)")
    ap.add_argument("--hang-severities", type=float, nargs="+", default=[0.0, 1.0, 2.0],
                    help="of those, where the methods' SKTs are hung (default 0 1 2; 0 is the "
                         "clean reference)")
    ap.add_argument("--methods", nargs="+", choices=[*LEARNED, *PROPOSING],
                    default=[*LEARNED, *PROPOSING], help="learned methods (default: all)")
    ap.add_argument("--no-seeds", action="store_true",
                    help=f"leave out {DEFAULT_METHOD}'s extra training seeds (make seeds)")
    ap.add_argument("--split", choices=sorted(SPLITS), default="test",
                    help="test supports and objects (default), or validation supports with the "
                         "training objects (for choices about a model)")
    args = ap.parse_args(argv)
    if not set(args.hang_severities) <= set(args.severities) or 0.0 not in args.hang_severities:
        ap.error("--hang-severities: must include 0 (the clean reference) and be among "
                 "--severities")
    params = load_params(args.params)
    # one thread: the same SKTs on any machine, and no spinning threads beside the trials' pool
    torch.set_num_threads(1)
    T = params.clustering.T
    models = {m: (m, load_models(args.data_root, [m], T)) for m in args.methods}
    if DEFAULT_METHOD in args.methods and not args.no_seeds:
        for label, folder in seed_models(args.data_root, args.params.resolve().parent,
                                         DEFAULT_METHOD).items():
            models[f"{DEFAULT_METHOD}{SEED_SEP}{label}"] = (
                DEFAULT_METHOD, load_models(folder.parents[1], [DEFAULT_METHOD], T))
    cfgs = [c.cfg for _, loaded in models.values() for c in loaded.values()]
    if len({(c.n_points, tuple(c.centres)) for c in cfgs}) != 1:
        raise DataError("the models take different clouds (n_points, centres): "
                        f"{sorted({(c.n_points, tuple(c.centres)) for c in cfgs})}")
    cfg = cfgs[0]
    views = evaluate_views(args, params, cfg)
    probes = load_probes(args.data_root) if any(
        m == "skt_flow" for m, _ in models.values()) else None
    cases = predict_views(views, params, models, params.sim_eval.setup_fallbacks, probes)
    trials = run_hangs(views, cases, params)
    rows = row_tables(trials)
    from tools.camera_report import summarize, write_report  # it reads this module's constants

    m = summarize(views, rows, args, params.common.seed)
    write_metrics(args.reports_dir, m)
    write_json_atomic(args.reports_dir / "outcomes.json", {  # to pair two runs view by view
        label: {f"{sev:g}/{mode}": {f"{r.support_id}/{r.view}/{r.object_id}": bool(r.success)
                                    for r in g.itertuples()}
                for (sev, mode), g in t.groupby(["severity", "mode"], sort=False)}
        for label, t in rows.items()})
    write_report(args.reports_dir, m, views)
    for mode, f in m["frame"].items():
        print(f"{MODES[mode]}: {100 * f['within_tol_rate']:.0f} % within {FRAME_TOL_MM:g} mm / "
              f"{FRAME_TOL_DEG:g}°, median {f['translation_mm_median']:.2f} mm")
    for label, k in m["kept"].items():
        print(f"{label}: clean {100 * k['clean']:.1f} %, at severity {HEADLINE:g} "
              f"(--camera --up) {100 * k['camera']:.1f} %, kept × on every level: "
              f"{'yes' if k['meets'] else 'no'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
