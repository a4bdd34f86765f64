"""Where SCTDN's one SKT loses the objects on Very Hard hooks (``make train-diagnostics``,
after ``make repro``): every training object swept along it, beside the ground truth.

``sim_eval`` and ``tools/val_sim.py`` say *that* SCTDN hangs nothing on Very Hard hooks, and
nearly every failure is ``collided_before_hang``. This says *where*. For each validation
support of ``--level``, in its evaluated view (``tools/val_sim.py``'s, drawn as ``sim_eval``
draws a test support's), SCTDN's read-out (``data/train``, the cloud check and all) gives one
SKT; every training object is swept along it and along the support's stored SKT 0 by the
exact mesh check ``rrt_skts`` re-checks with (:func:`tools.object_sweeps.object_sweeper`
at its ``recheck_spacing_m``, the executed path at ``recheck_step_m``). Per sweep: the least
clearance (negative: penetration into the support, mm; the check reads no deeper than its
shell) and where along the executed path it lies (0: the path's far end, where the object
starts; 1: the hang). A sweep is clear within ``rrt_skts``' ``SWEEP_TOL_M``, as the stage's
``test_sweep_clear_rate`` counts it.

Only the support's mesh is checked, not the wall, and the object is rigid at its keypoint
frame: a floating object, not the arm's grasp, so the sweep is a stricter judge than the
simulation (the stored SKT clears fewer objects here than the oracle hangs). What it is
for is the comparison on the same objects: the ground truth's path against SCTDN's.

Written to ``reports/train/sctdn_sweeps.{json,md,png}``; the picture shows each support
from the side (support x–z): its cloud, its stored SKTs, SCTDN's SKT, and the keypoint's
position at the deepest penetration of each object that does not clear. Not part of
``dvc repro`` and not a DVC output: a documented run whose numbers docs/pipeline.md quotes.
"""

import argparse
import json
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from skt_lib.config import LEVELS
from skt_lib.config.params_file import load_params
from skt_lib.geometry.export import read_obj
from skt_lib.io import write_json_atomic, write_text_atomic
from skt_lib.learning.predictor import SktPredictor
from skt_lib.planning.skts import SktObject, load_probe_objects
from stages._common import run_items
from stages.rrt_skts import SWEEP_TOL_M
from tools.object_sweeps import object_sweeper
from tools.val_sim import validation_set

OUT = Path("reports/train")


@dataclass(frozen=True)
class SweepTask:
    support_id: str
    family: str
    mesh: str
    paths: tuple[tuple[str, np.ndarray], ...]  # (name, positions (T, 3), ξ_0 first)
    objects: tuple[SktObject, ...]
    spacing_m: float
    step_m: float


def deepest(per_pose: np.ndarray) -> tuple[float, float]:
    """(least clearance, where it lies: its share of the path, 0 the far end, 1 the hang)
    of one sweep's clearance per executed pose (far end first)."""
    if not len(per_pose):
        raise ValueError("per_pose: an empty sweep")
    i = int(np.argmin(per_pose))
    return float(per_pose[i]), i / max(1, len(per_pose) - 1)


def sweep(task: SweepTask) -> dict:
    """Every object of ``task`` along each of its paths: ``{"support_id", "family",
    "sweeps": {path name: [{object_id, clearance_mm, deepest_at, keypoint}]}}``
    (``keypoint``: the object's keypoint (m, support frame) at the deepest pose)."""
    (support,) = read_obj(task.mesh)
    out = {name: [] for name, _ in task.paths}
    for o in task.objects:
        checker, along = object_sweeper(support, o, task.spacing_m, task.step_m)
        for name, positions in task.paths:
            keypoint_poses, object_poses = along(positions)
            clearance, at = deepest(checker.per_pose(object_poses))
            i = round(at * (len(keypoint_poses) - 1))
            out[name].append({"object_id": o.object_id, "clearance_mm": 1000 * clearance,
                              "deepest_at": at,
                              "keypoint": keypoint_poses[i, :3, 3].round(5).tolist()})
    return {"support_id": task.support_id, "family": task.family, "sweeps": out}


def clear(row: dict) -> bool:
    return row["clearance_mm"] >= -1000 * SWEEP_TOL_M


def summary(results: list[dict]) -> dict:
    """Per path: the share of (support, object) sweeps that clear, the median least clearance,
    and where the sweeps that do not clear are deepest (first half of the path, second half)."""
    out = {}
    for name in ("stored", "sctdn"):
        rows = [r for res in results for r in res["sweeps"][name]]
        failing = [r["deepest_at"] for r in rows if not clear(r)]
        out[name] = {"n_sweeps": len(rows), "clear_rate": float(np.mean([clear(r) for r in rows])),
                     "clearance_mm_median": float(np.median([r["clearance_mm"] for r in rows])),
                     "failing_deepest_in_first_half": int(sum(a < 0.5 for a in failing)),
                     "failing_deepest_in_second_half": int(sum(a >= 0.5 for a in failing))}
    return out


def picture(results: list[dict], clouds: dict, paths: dict, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(results)
    cols = min(5, n)
    rows = -(-n // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(3.6 * cols, 3.4 * rows), squeeze=False)
    for ax in axes.ravel()[n:]:
        ax.axis("off")
    for ax, res in zip(axes.ravel(), results):
        sid = res["support_id"]
        c = clouds[sid]
        ax.scatter(c[:, 0], c[:, 2], s=1, c="0.7", label="cloud (view)")
        for j, g in enumerate(paths[sid]["stored_all"]):
            ax.plot(g[:, 0], g[:, 2], "g-", lw=0.8, label="stored SKTs" if j == 0 else None)
        p = paths[sid]["sctdn"]
        ax.plot(p[:, 0], p[:, 2], "b-", lw=1.8, label="SCTDN's SKT")
        hits = np.array([r["keypoint"] for r in res["sweeps"]["sctdn"] if not clear(r)])
        if len(hits):
            ax.plot(hits[:, 0], hits[:, 2], "rx", ms=5, label="keypoint at deepest cut")
        n_clear = {k: sum(map(clear, v)) for k, v in res["sweeps"].items()}
        ax.set_title(f"{sid} ({res['family']})\nclear: stored {n_clear['stored']}/"
                     f"{len(res['sweeps']['stored'])}, SCTDN {n_clear['sctdn']}/"
                     f"{len(res['sweeps']['sctdn'])}", fontsize=8)
        ax.set_aspect("equal")
        ax.tick_params(labelsize=6)
    axes.ravel()[0].legend(fontsize=6, loc="lower right")
    fig.tight_layout()
    fig.savefig(path, dpi=72)
    plt.close(fig)


def report(data: dict, png: str) -> str:
    s = data["summary"]
    lines = ["# SCTDN's SKT swept with the training objects",
             "",
             f"Written by `tools/sctdn_sweeps.py` (`make train-diagnostics`) on the committed "
             f"params and the artifacts of `make repro`: the {data['n_supports']} validation "
             f"supports of level `{data['level']}`, each in its evaluated view, × the "
             f"{data['n_objects']} training objects, swept along SCTDN's one SKT and along the "
             f"support's stored SKT 0 (exact mesh check; support only, no wall; clear within "
             f"{data['sweep_tol_mm']:.0f} mm).",
             "",
             "| path | sweeps | clear | median least clearance (mm) | failing: deepest in the "
             "first half | … in the second half (toward the hang) |",
             "|---|---|---|---|---|---|"]
    for name, label in (("stored", "stored SKT 0"), ("sctdn", "SCTDN")):
        v = s[name]
        lines.append(f"| {label} | {v['n_sweeps']} | {100 * v['clear_rate']:.0f} % | "
                     f"{v['clearance_mm_median']:.1f} | {v['failing_deepest_in_first_half']} | "
                     f"{v['failing_deepest_in_second_half']} |")
    lines += ["", "Per support (objects clear of the support along each path):", "",
              "| support | family | stored SKT 0 | SCTDN |", "|---|---|---|---|"]
    for r in data["supports"]:
        k = {name: sum(map(clear, v)) for name, v in r["sweeps"].items()}
        lines.append(f"| {r['support_id']} | {r['family']} | {k['stored']} | {k['sctdn']} |")
    lines += ["", f"![every support of the level from the side]({png})", "",
              "Green: the support's stored SKTs; blue: SCTDN's; red crosses: the object's "
              "keypoint where each object that does not clear cuts deepest."]
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="tools/sctdn_sweeps.py", description=__doc__.splitlines()[0])
    ap.add_argument("--params", default="params.yaml", type=Path)
    ap.add_argument("--data-root", default="data", type=Path)
    ap.add_argument("--level", default="very_hard", choices=LEVELS)
    ap.add_argument("--out", default=OUT, type=Path)
    args = ap.parse_args(argv)
    params = load_params(args.params)
    p, T, seed = params.sim_eval, params.clustering.T, params.common.seed
    supports, _, _ = validation_set(args.data_root, T, seed, p)
    supports = [s for s in supports if s.difficulty == args.level]
    if not supports:
        print(f"ERROR: {args.data_root}: no validation support of level {args.level} with an "
              "SKT", file=sys.stderr)
        return 2
    predictor = SktPredictor.load(args.data_root / "train")
    _, objects, _ = load_probe_objects(args.data_root)
    tasks, clouds, paths = [], {}, {}
    for s in supports:
        skt = predictor.predict(s.cloud)
        clouds[s.support_id] = s.cloud
        paths[s.support_id] = {"sctdn": skt.positions, "stored_all": [s.gt, *s.others]}
        tasks.append(SweepTask(s.support_id, s.family, s.mesh,
                               (("stored", s.gt), ("sctdn", skt.positions)), tuple(objects),
                               params.rrt_skts.recheck_spacing_m, params.rrt_skts.recheck_step_m))
    results, _, crashed = run_items(sweep, tasks, params.compute, "supports")
    if crashed:
        print(f"ERROR: the sweeps of {crashed[0][0].support_id} failed: {crashed[0][1]}",
              file=sys.stderr)
        return 1
    results.sort(key=lambda r: r["support_id"])
    data = {"level": args.level, "n_supports": len(results), "n_objects": len(objects),
            "sweep_tol_mm": 1000 * SWEEP_TOL_M, "summary": summary(results), "supports": results}
    args.out.mkdir(parents=True, exist_ok=True)
    write_json_atomic(args.out / "sctdn_sweeps.json", data)
    picture(results, clouds, paths, args.out / "sctdn_sweeps.png")
    write_text_atomic(args.out / "sctdn_sweeps.md", report(data, "sctdn_sweeps.png"))
    print(json.dumps(data["summary"], indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
