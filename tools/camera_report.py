"""``make camera``'s figures: the frame's errors and checks, and every Table I row's hang
success against the sensor's severity, judged against its clean success (severity 0, the
true frame) on the same views (:mod:`tools.camera_eval` runs them)."""

from pathlib import Path

import numpy as np
import pandas as pd

from skt_lib.config import LEVELS
from skt_lib.eval.methods import PROPOSING
from skt_lib.eval.protocol import SINGLE
from skt_lib.stats import bootstrap_mean_interval, paired_comparison, wilson_interval
from tools.camera_eval import (
    DEFAULT_METHOD, FRAME_TOL_DEG, FRAME_TOL_MM, HEADLINE, MODES, SEED_SEP,
)
from viz.report import Report

#: Where a row is judged: what ``skt predict --camera --up`` gives at the headline severity,
#: against the clean reference (a perfect sensor, the true frame), view for view.
CLEAN, CAMERA = "0/true", f"{HEADLINE:g}/up"
#: The bar a row is held to (kept × clean at the headline severity, All and every level),
#: and the harsher sensor every row is also shown at.
KEPT_MIN, SEVERE = 0.9, "2/up"


def default_row() -> str:
    """The one-SKT row of ``skt predict``'s default model."""
    return DEFAULT_METHOD + (SINGLE if DEFAULT_METHOD in PROPOSING else "")


def _at(t: pd.DataFrame, key: str) -> pd.DataFrame:
    sev, mode = key.split("/")
    return t[(t["severity"] == float(sev)) & (t["mode"] == mode)].sort_values(
        ["support_id", "view"])


def _rate(t: pd.DataFrame) -> dict:
    return {"all": float(t["success"].mean()),
            **{lv: float(t.loc[t["difficulty"] == lv, "success"].mean())
               for lv in LEVELS if (t["difficulty"] == lv).any()}}


def _ratio(a: dict, b: dict) -> dict:
    """``a / b`` key by key (None where ``b`` is 0: nothing to keep)."""
    return {k: (a[k] / b[k] if b.get(k) else None) for k in a}


def _paired(a: pd.DataFrame, b: pd.DataFrame, rng) -> dict:
    """``a`` − ``b`` on the same views (both sorted by support and view)."""
    if list(zip(a["support_id"], a["view"])) != list(zip(b["support_id"], b["view"])):
        raise ValueError("paired rows: not the same views")
    x, y = a["success"].to_numpy(), b["success"].to_numpy()
    c = paired_comparison(x, y)
    diff = x.astype(float) - y.astype(float)
    return {"difference": float(diff.mean()), "n_a_only": c.n_a_only, "n_b_only": c.n_b_only,
            "p_value": c.p_value,
            "support_bootstrap_ci95": bootstrap_mean_interval(diff, b["support_id"].to_numpy(),
                                                              rng)}


def _kept(t: pd.DataFrame, rng) -> dict:
    """A row's clean success and what it keeps of it at the headline severity (and at
    severity 2 where it ran), per level, with the paired difference."""
    clean, cam = _rate(_at(t, CLEAN)), _rate(_at(t, CAMERA))
    kept = _ratio(cam, clean)
    levels = {lv: r for lv, r in kept.items() if lv != "all" and r is not None}
    worst = min(levels, key=levels.get) if levels else None
    out = {"clean": clean["all"], "camera": cam["all"], "all": kept["all"],
           "by_level": {lv: kept[lv] for lv in LEVELS if lv in kept},
           "worst_level": levels.get(worst), "worst_level_name": worst,
           "meets": bool(levels) and min(levels.values()) >= KEPT_MIN
           and kept["all"] is not None and kept["all"] >= KEPT_MIN,
           "paired": _paired(_at(t, CAMERA), _at(t, CLEAN), rng)}
    severe = _at(t, SEVERE)
    if len(severe):
        out["severe_all"] = _ratio(_rate(severe), clean)["all"]
    return out


def _over_seeds(rows: dict[str, pd.DataFrame]) -> dict:
    """Rows run with extra training seeds (``<row> seed <s>`` beside ``<row>``): the mean
    and range over the seeds of the clean and headline success per level, and the mean's
    kept ratio."""
    out = {}
    for base in [r for r in rows if SEED_SEP not in r]:
        labels = [base, *[r for r in rows if r.startswith(base + SEED_SEP)]]
        if len(labels) < 2:
            continue
        per = {key: [_rate(_at(rows[r], key)) for r in labels] for key in (CLEAN, CAMERA, SEVERE)
               if len(_at(rows[base], key))}
        mean = {key: {k: float(np.mean([x[k] for x in xs])) for k in xs[0]}
                for key, xs in per.items()}
        kept = _ratio(mean[CAMERA], mean[CLEAN])
        levels = [kept[lv] for lv in LEVELS if kept.get(lv) is not None]
        out[base] = {"rows": labels, "mean": mean,
                     "range": {key: {k: [min(x[k] for x in xs), max(x[k] for x in xs)]
                                     for k in xs[0]} for key, xs in per.items()},
                     "kept": kept, "worst_level": min(levels) if levels else None,
                     "severe_all": (_ratio(mean[SEVERE], mean[CLEAN])["all"]
                                    if SEVERE in mean else None)}
    return out


def _frame_summary(views) -> dict:
    out = {}
    for mode in ("up", "level"):
        seen = [v for v in views if mode in v["ready"] or mode in v["refused"]]
        if not seen:
            continue
        err = np.array([v["err"].get(mode, (np.inf, np.inf)) for v in seen]).reshape(-1, 2)
        fin = err[np.isfinite(err).all(1)]
        warned = np.array([v["warned"].get(mode, False) for v in seen])
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
            "seconds_median": float(np.median([v["seconds"][mode] for v in seen
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


def summarize(views, rows: dict[str, pd.DataFrame], args, seed: int) -> dict:
    """metrics.json: the frame, and per Table I row (``rows``: :func:`row_tables`') its hang
    success by ``severity/mode``, what it keeps of its clean success, over seeds where it
    has them; the default predictor's paired differences between modes."""
    rng = np.random.default_rng(seed)
    head = [v for v in views if v["severity"] == HEADLINE]
    main = default_row()
    pairs = [(f"{HEADLINE:g}/{m}", f"{HEADLINE:g}/true") for m in ("up", "level", "assumed")]
    pairs += [(CLEAN, f"{HEADLINE:g}/true"), (CAMERA, CLEAN), (SEVERE, CLEAN)]
    paired = {}
    if main in rows:
        t = rows[main]
        paired = {f"{a}-{b}": _paired(_at(t, a), _at(t, b), rng) for a, b in pairs
                  if len(_at(t, a)) and len(_at(t, b))}
    any_rows = next(iter(rows.values()))
    return {"rows": list(rows), "default_row": main, "split": args.split,
            "n_views": len(head), "views_per_support": args.views,
            "n_supports": int(any_rows["support_id"].nunique()), "headline_severity": HEADLINE,
            "severities": list(args.severities), "hang_severities": list(args.hang_severities),
            "frame": _frame_summary(head),
            "frame_by_severity": {f"{sev:g}": f["up"] for sev in args.severities
                                  for f in [_frame_summary([v for v in views
                                                            if v["severity"] == sev])]
                                  if "up" in f},
            "hang": {label: {f"{sev:g}/{mode}": _hang_summary(g)
                             for (sev, mode), g in t.groupby(["severity", "mode"], sort=False)}
                     for label, t in rows.items()},
            "kept": {label: _kept(t, rng) for label, t in rows.items()},
            "seeds": _over_seeds(rows), "paired": paired}


def _pct(x) -> str:
    return "–" if x is None or (isinstance(x, float) and np.isnan(x)) else f"{100 * x:.0f}"


def _times(x) -> str:
    return "–" if x is None else f"{x:.2f}"


def _pct_ci(h: dict) -> str:
    lo, hi = h["success_ci95"]
    return f"{100 * h['success']:.0f} [{100 * lo:.0f}–{100 * hi:.0f}]"


def _diff(c: dict) -> str:
    lo, hi = c["support_bootstrap_ci95"]
    return f"{100 * c['difference']:+.0f} [{100 * lo:+.0f}, {100 * hi:+.0f}]"


def write_report(rep: Path, m: dict, views) -> None:
    report = Report("camera", rep)
    split = "validation" if m["split"] == "val" else "test"
    report.text(
        f"Every learned row of Table I on {m['n_views']} depth-camera views ({m['n_supports']} "
        f"{split} supports × {m['views_per_support']} cameras of `render_views`' ring, the wall "
        "in view, the sensor model of `skt_lib/perception/sensor.py`), each row's SKTs executed "
        "by `sim_eval`'s executor (Panda, grasps, physics, success predicate) on one "
        f"{'training' if m['split'] == 'val' else 'test'} object per view, the same object for a "
        "view at every severity, in every mode and for every row. A row is judged against its "
        "own clean success (severity 0, the true frame) on the same views. "
        "Regenerate with `make camera`.")
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
                "the frame and the cleaning, without a network.")
    _rows_section(report, m)
    _default_section(report, m)
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
    _figure(report, m, views)
    report.write()


def _rows_section(report: Report, m: dict) -> None:
    keys = [f"{s:g}/{mode}" for s in m["hang_severities"] for mode in ("true", "up")]
    report.heading("Every learned row against the sensor")
    report.table(["row", *[f"{k.split('/')[0]} {MODES[k.split('/')[1]]}" for k in keys],
                  f"kept × clean, {CAMERA} (All)", "worst level", "2/up kept × (All)"],
                 [[f"`{label}`", *[_pct(m["hang"][label][k]["success"])
                                   if k in m["hang"][label] else "–" for k in keys],
                   _times(k["all"]),
                   f"{_times(k['worst_level'])} ({k['worst_level_name']})"
                   if k["worst_level_name"] else "–",
                   _times(k.get("severe_all"))]
                  for label, k in m["kept"].items() if SEED_SEP not in label])
    report.text(f"Success in % of {m['n_views']} views per cell. \"kept × clean\": the row's "
                f"success from `skt predict --camera --up` at severity {HEADLINE:g} over its "
                f"success at severity 0 from the true frame; the bar is {KEPT_MIN:g} × on All and "
                "on every level. A proposing method's `@1` row is its first proposal, the row "
                "without is the best of its proposals (Table I's).")
    report.heading(f"Kept at severity {HEADLINE:g} (`--camera --up` over clean), per level")
    report.table(["row", "clean All", *LEVELS, "difference (points) [support bootstrap 95 %]",
                  f"≥ {KEPT_MIN:g} × everywhere"],
                 [[f"`{label}`", _pct(k["clean"]), *[_times(k["by_level"].get(lv))
                                                      for lv in LEVELS],
                   _diff(k["paired"]), "yes" if k["meets"] else "no"]
                  for label, k in m["kept"].items()])
    if m["seeds"]:
        report.heading("Over training seeds")
        report.table(["row", "seeds", "clean All (range)", f"{CAMERA} All (range)",
                      *[f"kept × {lv}" for lv in LEVELS], "kept × All", "2/up kept × (All)"],
                     [[f"`{base}`", len(s["rows"]),
                       f"{_pct(s['mean'][CLEAN]['all'])} ({_pct(s['range'][CLEAN]['all'][0])}–"
                       f"{_pct(s['range'][CLEAN]['all'][1])})",
                       f"{_pct(s['mean'][CAMERA]['all'])} ({_pct(s['range'][CAMERA]['all'][0])}–"
                       f"{_pct(s['range'][CAMERA]['all'][1])})",
                       *[_times(s["kept"].get(lv)) for lv in LEVELS], _times(s["kept"]["all"]),
                       _times(s["severe_all"])]
                      for base, s in m["seeds"].items()])
        report.text("Means over the training seeds (`make seeds`' models, on the same views and "
                    "objects); kept × is the mean camera success over the mean clean success.")


def _default_section(report: Report, m: dict) -> None:
    main = m["default_row"]
    if main not in m["hang"]:
        return
    report.heading(f"The default predictor (`{main}`): the ladder in every mode")
    report.table(["severity", "mode", "All (Wilson 95 %)", *LEVELS, "frame within 5 mm / 2°"],
                 [[sev, MODES[mode], _pct_ci(h), *[_pct(h["by_level"].get(lv)) for lv in LEVELS],
                   f"{100 * m['frame_by_severity'][sev]['within_tol_rate']:.0f} %"
                   if mode == "up" and sev in m["frame_by_severity"] else ""]
                  for key, h in sorted(m["hang"][main].items(),
                                       key=lambda kv: (float(kv[0].split("/")[0]),
                                                       list(MODES).index(kv[0].split("/")[1])))
                  for sev, mode in [key.split("/")]])
    report.heading("Paired differences of the default predictor (same views and objects)")
    report.table(["a − b", "difference (points) [support bootstrap 95 %]",
                  "discordant (a only / b only)", "McNemar p"],
                 [[k.replace("-", " − "), _diff(c), f"{c['n_a_only']} / {c['n_b_only']}",
                   f"{c['p_value']:.3g}"] for k, c in m["paired"].items()])


def _figure(report: Report, m: dict, views) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 3, figsize=(13, 3.6))
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
    for label, hang in m["hang"].items():
        if SEED_SEP in label:
            continue
        pts = sorted((float(key.split("/")[0]), h["success"]) for key, h in hang.items()
                     if key == CLEAN or (key.endswith("/up") and not key.startswith("0/")))
        x, y = np.array(pts).T
        ax[2].plot(x, 100 * y, marker="o", lw=2.5 if label == m["default_row"] else 1,
                   label=label)
    ax[2].set(xlabel="sensor severity (0: true frame; else --camera --up)",
              ylabel="hang success (%)", ylim=(0, 100))
    ax[2].legend(fontsize=7, ncol=2)
    fig.tight_layout()
    fig.savefig(report.figure("frame_errors.png", f"Support-frame error per view at severity "
                                                  f"{HEADLINE:g} (dashed: 5 mm), and every row's "
                                                  "hang success against severity"), dpi=110)
    plt.close(fig)

