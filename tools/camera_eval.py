"""From a real depth camera (``make camera``, after ``make repro``): ``skt predict --camera``
on the views a depth camera would give — the wall in view, the sensor model of
:mod:`skt_lib.perception.sensor` at severities 0 (perfect) to 4 — against the true camera
pose.

Each support of the split gets ``--views`` camera poses drawn from ``render_views``' ring
(seeded), each paired with one object (every object in turn; the same one for a view at
every severity and in every mode). Per view and severity, one cloud, brought to the model
(SCTDN, ``--model``) in each mode of :data:`MODES`:

- ``true``: moved by the true camera pose, the wall cut 4 mm in front of the true plane —
  the SKT "predicted from the true frame";
- ``assumed``: moved by the pose a user would assume (the sensor model's pose error: 1 cm
  and 2° at severity 1), the wall cut the same way, as ``skt predict --frame`` would be fed;
- ``up`` / ``level``: ``skt predict --camera`` with ``--up`` (the true gravity in the camera
  frame, as an IMU gives it) or ``--level`` (severity 1 only); the estimated frame's error
  against the truth is recorded.

Every SKT is mapped from the frame it was predicted in to the true one (what a robot given
that frame executes) and run by ``sim_eval``'s executor (Panda, grasps, physics, success
predicate). Writes ``metrics.json``, ``report.md``, ``frame_errors.png`` and
``outcomes.json`` (every trial's verdict by ``severity/mode`` and ``support/view/object``, to
pair two runs, e.g. two models) to ``--reports-dir`` (default ``reports/camera``); nothing
under the data root changes.
"""

import argparse
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
from tqdm import tqdm

from skt_lib.cli.predict import predict_camera, predict_cloud
from skt_lib.config import LEVELS
from skt_lib.config.params_file import load_params
from skt_lib.errors import InputError
from skt_lib.eval.protocol import load_test_set, make_task, trial_settings
from skt_lib.geometry.export import read_obj
from skt_lib.geometry.se3 import invert, transform_points
from skt_lib.io import write_json_atomic
from skt_lib.learning.predictor import SktPredictor
from skt_lib.perception.sensor import CameraScene, Intrinsics, SensorModel, camera_view
from skt_lib.perception.views import support_cameras
from skt_lib.perception.wall_frame import WallSettings
from skt_lib.seeding import item_rng
from skt_lib.sim.execute import run_trial
from skt_lib.stats import bootstrap_mean_interval, paired_comparison, wilson_interval
from stages._common import run_items
from viz.report import Report, write_metrics

METHOD = "sctdn"
#: Acceptance of the frame estimate (issue: within 5 mm and 2°).
FRAME_TOL_MM, FRAME_TOL_DEG = 5.0, 2.0
#: How a view becomes the support-frame cloud the model sees: the wall cut at the true plane
#: after the true transform; ``skt predict --camera --up``; ``--camera --level``.
MODES = {"true": "true frame", "assumed": "`--frame` off by the pose error",
         "up": "`--camera --up`", "level": "`--camera --level`"}
#: --split: (support split, object split); validation pairs the training objects, as val_sim.
SPLITS = {"test": ("test", "test"), "val": ("val", "train")}
#: The sensor model's severity where the frame and the hang are judged; --level runs there.
HEADLINE = 1.0


def frame_error(est: np.ndarray, true: np.ndarray) -> tuple[float, float]:
    """(translation mm, rotation °) of ``est @ inv(true)``: where the true support frame
    lands in the estimated one."""
    e = est @ invert(true)
    angle = np.degrees(np.arccos(np.clip((np.trace(e[:3, :3]) - 1) / 2, -1.0, 1.0)))
    return 1000 * float(np.linalg.norm(e[:3, 3])), float(angle)


def _in_truth(pred, est: np.ndarray, pose: np.ndarray):
    """The predicted SKT's positions (and fallbacks) mapped from the estimated support frame
    to the true one: what a robot executes given that estimate."""
    to_true = pose @ invert(est)
    return (transform_points(to_true, pred.skt.positions),
            tuple(transform_points(to_true, f) for f in pred.skt.fallbacks))


def evaluate_views(args, params, predictor) -> list[dict]:
    """Per view (support, object, camera) and severity: the frame error and the SKT
    (positions, fallbacks; true support frame) of every mode, or why it was refused."""
    p, seed = params.render_views, params.common.seed
    supports, objects, _ = load_test_set(args.data_root, params.clustering.T, seed,
                                         params.sim_eval.grasp_pitch_deg,
                                         params.sim_eval.grasp_rolls_deg,
                                         params.sim_eval.grasp_yaws_deg, *SPLITS[args.split],
                                         grasp_sphere=params.sim_eval.grasp_sphere_directions)
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
                modes = [m for m in args.modes if m != "level" or sev == HEADLINE]
                views.append({"support": s, "object": o, "view": int(v), "severity": sev,
                              **_predict_modes(predictor, cam, modes, f"{s.support_id} view {v}")})
    return views


def _predict_modes(predictor, cam, modes, name: str) -> dict:
    """One camera view brought to the model in each of ``modes``: the SKTs (true support
    frame), the refusals, and for ``--camera`` the frame errors and seconds."""
    out = {"skts": {}, "refused": {}, "err": {}, "seconds": {}, "warned": {}}
    for mode in modes:
        t0 = time.perf_counter()
        try:
            if mode in ("true", "assumed"):  # moved by that pose, wall cut 4 mm off its plane
                frame = cam.pose if mode == "true" else cam.assumed
                cloud = transform_points(frame, cam.points)
                pred = predict_cloud(predictor, cloud[cloud[:, 0] > WallSettings.off_wall_m],
                                     "m", None, 0, name)
                out["skts"][mode] = ((pred.skt.positions, pred.skt.fallbacks) if mode == "true"
                                     else _in_truth(pred, cam.assumed, cam.pose))
                continue
            up = cam.pose[:3, :3].T @ np.array([0.0, 0.0, 1.0]) if mode == "up" else None
            pred = predict_camera(predictor, cam.points, up, seed=0, name=name)
        except InputError as err:
            out["refused"][mode] = str(err)
            continue
        out["seconds"][mode] = time.perf_counter() - t0
        out["err"][mode] = frame_error(pred.camera_to_support, cam.pose)
        out["warned"][mode] = bool(pred.warnings)  # what `skt predict` prints to its user
        out["skts"][mode] = _in_truth(pred, pred.camera_to_support, cam.pose)
    return out


def run_hangs(views, params) -> pd.DataFrame:
    """One trial per view and mode (a refused view fails); the rows of every trial."""
    settings = trial_settings(params.sim_eval, params.contact_sim)
    n_fb = params.sim_eval.setup_fallbacks
    tasks, keys = [], []
    for i, v in enumerate(views):
        for mode, (pos, fb) in v["skts"].items():
            tasks.append(make_task(METHOD, v["support"], v["object"], pos, settings,
                                   fallbacks=fb[:n_fb]))
            keys.append((i, mode))
    results, _, crashes = run_items(run_trial, tasks, params.compute, "trials")
    if crashes:
        raise RuntimeError(f"{len(crashes)} trials crashed, first: {crashes[0][0].trial_id}")
    done = {key: r["row"] for key, r in zip(keys, results)}
    out = []
    for i, v in enumerate(views):
        for mode in [*v["skts"], *v["refused"]]:
            r = done.get((i, mode))
            out.append({"view_index": i, "support_id": v["support"].support_id,
                        "difficulty": v["support"].difficulty, "object_id": v["object"].object_id,
                        "view": v["view"], "severity": v["severity"], "mode": mode,
                        "success": bool(r and r["success"]),
                        "failure_reason": r["failure_reason"] if r else "refused"})
    return pd.DataFrame(out)


def _frame_summary(views) -> dict:
    out = {}
    for mode in ("up", "level"):
        err = np.array([v["err"].get(mode, (np.inf, np.inf)) for v in views if mode in v["skts"]
                        or mode in v["refused"]]).reshape(-1, 2)
        if len(err) == 0:
            continue
        fin = err[np.isfinite(err).all(1)]
        warned = np.array([v["warned"].get(mode, False) for v in views if mode in v["skts"]
                           or mode in v["refused"]])
        off = (err[:, 0] > FRAME_TOL_MM) | (err[:, 1] > FRAME_TOL_DEG)  # refused: inf, off
        silent = off & np.isfinite(err).all(1) & ~warned
        out[mode] = {
            "n_views": len(err), "n_refused": int(len(err) - len(fin)),
            "within_tol_rate": float((~off).mean()),
            "n_warned": int(warned.sum()),
            "n_warned_within_tol": int((warned & ~off).sum()),
            "n_silent_off_tol": int(silent.sum()),  # beyond 5 mm / 2° without a word
            "n_silent_over_10mm": int((silent & (err[:, 0] > 10.0)).sum()),
            "translation_mm_median": float(np.median(fin[:, 0])),
            "translation_mm_p95": float(np.percentile(fin[:, 0], 95)),
            "translation_mm_max": float(fin[:, 0].max()),
            "rotation_deg_median": float(np.median(fin[:, 1])),
            "rotation_deg_max": float(fin[:, 1].max()),
            "seconds_median": float(np.median([v["seconds"][mode] for v in views
                                               if mode in v["seconds"]])),
        }
    return out


def _hang_summary(t: pd.DataFrame) -> dict:
    return {"n": len(t), "success": float(t["success"].mean()),
            "success_ci95": wilson_interval(int(t["success"].sum()), len(t)),
            "by_level": {lv: float(t.loc[t["difficulty"] == lv, "success"].mean())
                         for lv in LEVELS if (t["difficulty"] == lv).any()},
            "failures_by_reason": t.loc[~t["success"], "failure_reason"]
            .value_counts().sort_index().to_dict()}


def _paired(a: pd.DataFrame, b: pd.DataFrame, rng) -> dict:
    """``a`` − ``b`` on the same views (``view_index`` order of ``b``)."""
    a = a.set_index(["support_id", "view"]).loc[b.set_index(["support_id", "view"]).index]
    x, y = a["success"].to_numpy(), b["success"].to_numpy()
    c = paired_comparison(x, y)
    diff = x.astype(float) - y.astype(float)
    return {"difference": float(diff.mean()), "n_a_only": c.n_a_only, "n_b_only": c.n_b_only,
            "p_value": c.p_value,
            "support_bootstrap_ci95": bootstrap_mean_interval(diff, b["support_id"].to_numpy(),
                                                              rng)}


def summarize(views, trials: pd.DataFrame, args, seed: int) -> dict:
    rng = np.random.default_rng(seed)
    head = [v for v in views if v["severity"] == HEADLINE]
    rows = {f"{sev:g}/{mode}": _hang_summary(g) for sev in args.severities for mode in MODES
            for g in [trials[(trials["severity"] == sev) & (trials["mode"] == mode)]] if len(g)}
    at = {sev: {m: g.sort_values("view_index") for m, g in trials[trials["severity"] == sev]
                .groupby("mode")} for sev in args.severities}
    pairs = [((HEADLINE, m), (HEADLINE, "true")) for m in ("up", "level")]
    pairs += [((0.0, "true"), (HEADLINE, "true")), ((HEADLINE, "up"), (0.0, "true"))]
    paired = {f"{a[0]:g}/{a[1]}-{b[0]:g}/{b[1]}": _paired(at[a[0]][a[1]], at[b[0]][b[1]], rng)
              for a, b in pairs if a[1] in at.get(a[0], {}) and b[1] in at.get(b[0], {})}
    return {"method": METHOD, "split": args.split, "model": str(args.model or "data/train"),
            "n_views": len(head), "views_per_support": args.views,
            "n_supports": int(trials["support_id"].nunique()), "headline_severity": HEADLINE,
            "severities": list(args.severities), "frame": _frame_summary(head),
            "frame_by_severity": {f"{sev:g}": f["up"] for sev in args.severities
                                  for f in [_frame_summary([v for v in views
                                                            if v["severity"] == sev])]
                                  if "up" in f},
            "hang": rows, "paired": paired}


def _pct_ci(h: dict) -> str:
    lo, hi = h["success_ci95"]
    return f"{100 * h['success']:.0f} [{100 * lo:.0f}–{100 * hi:.0f}]"


def write_report(rep: Path, m: dict, views) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    report = Report("camera", rep)
    report.text(f"`skt predict --camera` on {m['n_views']} depth-camera views ({m['n_supports']} "
                f"{'validation' if m['split'] == 'val' else 'test'} supports × "
                f"{m['views_per_support']} cameras of `render_views`' ring, the "
                "wall in view, the sensor model of `skt_lib/perception/sensor.py`), "
                f"{m['method']}'s SKT executed by `sim_eval`'s executor (Panda, grasps, physics, "
                "success predicate) on one " + ("training" if m["split"] == "val" else "test") +
                " object per view (model: `" + m["model"] + "`), the same object for a view at "
                "every severity and in every mode. Regenerate with `make camera`.")
    report.heading(f"The support frame from the wall (severity {HEADLINE:g})")
    report.table(["mode", "within 5 mm and 2°", "origin error median / p95 / max (mm)",
                  "rotation median / max (°)", "refused", "seconds (median)"],
                 [[MODES[k], f"{100 * f['within_tol_rate']:.0f} %",
                   f"{f['translation_mm_median']:.2f} / {f['translation_mm_p95']:.2f} / "
                   f"{f['translation_mm_max']:.1f}",
                   f"{f['rotation_deg_median']:.3f} / {f['rotation_deg_max']:.2f}",
                   f["n_refused"], f"{f['seconds_median']:.2f}"]
                  for k, f in m["frame"].items()])
    report.text("`--up` is the true direction against gravity in the camera frame (an IMU's, "
                "without its error); `--level` takes up from the wall's vertical, the camera's "
                "image rows being horizontal (as every camera of the ring is). The seconds are "
                "the whole `predict_camera` call (frame, cleaning, network).")
    report.heading("Hang success against the sensor's severity (the ladder)")
    report.table(["severity", "mode", "All (Wilson 95 %)", *LEVELS, "frame within 5 mm / 2°"],
                 [[sev, MODES[mode], _pct_ci(h),
                   *[f"{100 * h['by_level'].get(lv, float('nan')):.0f}" for lv in LEVELS],
                   f"{100 * m['frame_by_severity'][sev]['within_tol_rate']:.0f} %"
                   if mode == "up" and sev in m["frame_by_severity"] else ""]
                  for key, h in m["hang"].items() for sev, mode in [key.split("/")]])
    report.heading("The frame's check against the severity (`--camera --up`)")
    report.table(["severity", "within 5 mm / 2°", "refused", "warned (of them within)",
                  "silent beyond 5 mm / 2°", "silent beyond 1 cm", "origin error median (mm)"],
                 [[sev, f"{100 * f['within_tol_rate']:.0f} %", f["n_refused"],
                   f"{f['n_warned']} ({f['n_warned_within_tol']})", f["n_silent_off_tol"],
                   f["n_silent_over_10mm"], f"{f['translation_mm_median']:.2f}"]
                  for sev, f in m["frame_by_severity"].items()])
    report.text(f"Of {m['n_views']} views per severity. A frame is refused (no wall, no "
                "structure) or, where the wall under the hook's foot is hidden, carries a "
                "warning that the frame's height may be off (`skt_lib/perception/wall_frame.py`, "
                "the check); \"silent\": off by more than that with neither.")
    report.text("Severity 0 is a perfect sensor, 1 the defaults (docs/pipeline.md, \"A depth "
                "camera's view\"), 2–4 every effect scaled up. \"true frame\": the cloud moved "
                "by the true camera pose and the wall cut at the true plane (4 mm) — the SKT "
                "\"predicted from the true frame\".")
    report.heading("Paired differences (same views and objects)")
    report.table(["a − b", "difference (points)", "support bootstrap 95 %",
                  "discordant (a only / b only)", "McNemar p"],
                 [[k.replace("-", " − "), f"{100 * c['difference']:+.0f}",
                   f"[{100 * c['support_bootstrap_ci95'][0]:+.0f}, "
                   f"{100 * c['support_bootstrap_ci95'][1]:+.0f}]",
                   f"{c['n_a_only']} / {c['n_b_only']}", f"{c['p_value']:.3g}"]
                  for k, c in m["paired"].items()])
    fig, ax = plt.subplots(1, 3, figsize=(12, 3.3))
    head = [v for v in views if v["severity"] == HEADLINE]
    for mode, c in (("up", "tab:blue"), ("level", "tab:orange")):
        err = np.array([v["err"][mode] for v in head if mode in v["err"]])
        if len(err) == 0:
            continue
        ax[0].hist(err[:, 0], bins=30, alpha=0.6, color=c, label=MODES[mode].strip("`"))
        ax[1].hist(err[:, 1], bins=30, alpha=0.6, color=c)
    ax[0].axvline(FRAME_TOL_MM, color="k", ls="--")
    ax[0].set(xlabel="origin error (mm)", ylabel="views")
    ax[1].set(xlabel="rotation error (°)")
    ax[0].legend()
    for mode, c in (("true", "tab:green"), ("up", "tab:blue")):
        pts = [(float(sev), h["success"], *h["success_ci95"])
               for key, h in m["hang"].items() for sev, md in [key.split("/")] if md == mode]
        if not pts:
            continue
        x, y, lo, hi = np.array(pts).T
        ax[2].errorbar(x, 100 * y, yerr=[100 * (y - lo), 100 * (hi - y)], color=c, marker="o",
                       capsize=3, label=MODES[mode].strip("`"))
    ax[2].set(xlabel="sensor severity", ylabel=f"{m['method']} hang success (%)", ylim=(0, 100))
    ax[2].legend()
    fig.tight_layout()
    fig.savefig(report.figure("frame_errors.png", f"Support-frame error per view at severity "
                                                  f"{HEADLINE:g} (dashed: 5 mm), and hang "
                                                  "success against severity (Wilson 95 %)"),
                dpi=110)
    plt.close(fig)
    report.write()


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="tools/camera_eval.py", description=__doc__.splitlines()[0])
    ap.add_argument("--params", default="params.yaml", type=Path)
    ap.add_argument("--data-root", default="data", type=Path)
    ap.add_argument("--reports-dir", default="reports/camera", type=Path)
    ap.add_argument("--views", type=int, default=5, help="views per test support (default 5)")
    ap.add_argument("--severities", type=float, nargs="+", default=[0.0, 1.0, 2.0, 3.0, 4.0],
                    help=f"sensor model severities (default 0 1 2 3 4; {HEADLINE:g} is the "
                         "headline)")
    ap.add_argument("--modes", nargs="+", choices=list(MODES), default=list(MODES),
                    help="how views reach the model (default: all; --level runs at severity "
                         f"{HEADLINE:g} only)")
    ap.add_argument("--split", choices=sorted(SPLITS), default="test",
                    help="test supports and objects (default), or validation supports with the "
                         "training objects (for choices about a model)")
    ap.add_argument("--model", type=Path, default=None,
                    help="SCTDN model folder (default: DATA_ROOT/train)")
    args = ap.parse_args(argv)
    params = load_params(args.params)
    predictor = SktPredictor.load(args.model or args.data_root / "train")
    views = evaluate_views(args, params, predictor)
    trials = run_hangs(views, params)
    m = summarize(views, trials, args, params.common.seed)
    write_metrics(args.reports_dir, m)
    write_json_atomic(args.reports_dir / "outcomes.json", {  # to pair two runs view by view
        key: {f"{r.support_id}/{r.view}/{r.object_id}": bool(r.success) for r in g.itertuples()}
        for key, g in ((f"{sev:g}/{mode}", g) for (sev, mode), g in
                       trials.groupby(["severity", "mode"], sort=False))})
    write_report(args.reports_dir, m, views)
    for mode, f in m["frame"].items():
        print(f"{MODES[mode]}: {100 * f['within_tol_rate']:.0f} % within {FRAME_TOL_MM:g} mm / "
              f"{FRAME_TOL_DEG:g}°, median {f['translation_mm_median']:.2f} mm")
    for key, h in m["hang"].items():
        print(f"severity {key}: {100 * h['success']:.1f} %")
    return 0


if __name__ == "__main__":
    sys.exit(main())
