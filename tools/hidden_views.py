"""Views that hide where a support leaves the wall (after ``make repro``): how often one of
``render_views``' 42 views shows none of a support's first centimetres in front of its wall
plate, which evaluated views (``sim_eval``'s one per test support, the same draw for
validation supports in ``tools/val_sim.py``) are such views, and how each method fares on
those supports against the rest.

Every generated support is a wall plate (``x ∈ [0, 1 cm]``, support frame) with its strokes
starting on the plate's front face, so a view that shows the support's link to the wall has
points in the band :data:`BAND_M` in front of it. A camera looking along a peg (about 3 % of
the ring's views) sees its knob, or its tip, and nothing of the rod behind
it: from that cloud no method can tell where the rod runs. A view is *hiding* when fewer
than :data:`MIN_POINTS` of its points lie in the band.

Written to ``<out>/hidden_views.{json,md,png}`` (default ``reports/sim_eval``): per split the
share of hiding views; the test and validation supports whose evaluated view hides; per
method of ``data/sim_eval/trials.parquet`` (first proposals: the one-SKT rows) the success on
those supports and on the rest; and a picture of each hiding evaluated test view beside the
same support's most revealing view. Not part of ``dvc repro`` and not a DVC output: a
documented run whose numbers docs/evaluation.md quotes. Reads only; no stage output changes.
"""

import argparse
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from skt_lib.config.params_file import load_params
from skt_lib.geometry.export import read_obj
from skt_lib.geometry.supports import PLATE_THICKNESS_M
from skt_lib.io import read_npz, read_table, write_json_atomic
from skt_lib.perception.views import RENDER_SPEC
from skt_lib.schemas import SUPPORTS
from skt_lib.seeding import item_rng

#: The band (m, support frame x) in front of the plate's front face where every generated
#: support's strokes leave the wall: 5–25 mm out (the first 5 mm: the plate's own edge in
#: views from the side).
BAND_M = (PLATE_THICKNESS_M + 0.005, PLATE_THICKNESS_M + 0.025)
#: The splits whose supports have an evaluated view (Table I's, validation in simulation).
EVALUATED = ("test", "val")
#: A view with fewer points than this in the band hides the support's link to the wall.
MIN_POINTS = 5


def band_counts(points: np.ndarray) -> np.ndarray:
    """``(V,)``: points of each view ``points (V, N, 3)`` (support frame) in :data:`BAND_M`."""
    x = np.asarray(points)[..., 0]
    return ((x > BAND_M[0]) & (x < BAND_M[1])).sum(axis=-1)


def evaluated_view(seed: int, support_id: str, n_views: int) -> int:
    """The view ``sim_eval`` (and ``tools/val_sim.py``) gives every method of a support."""
    return int(item_rng(seed, "sim_eval", support_id).integers(n_views))


def survey(root: Path, seed: int) -> pd.DataFrame:
    """One row per support with views: its split, level, band counts of every view, the
    evaluated view and its count."""
    supports = read_table(root / "mesh_gen" / "supports.parquet", SUPPORTS)
    rows = []
    for s in supports.itertuples():
        path = root / "render_views" / f"{s.support_id}.npz"
        if not path.is_file():
            continue
        counts = band_counts(read_npz(path, RENDER_SPEC)["points"])
        view = evaluated_view(seed, s.support_id, len(counts))
        rows.append({"support_id": s.support_id, "split": s.split, "difficulty": s.difficulty,
                     "mesh": str(root / "mesh_gen" / s.mesh_path), "counts": counts,
                     "view": view, "view_count": int(counts[view])})
    if not rows:
        raise SystemExit(f"ERROR: {root}/render_views: no views (run `make repro` first)")
    return pd.DataFrame(rows)


def by_method(trials: pd.DataFrame, hiding: set[str]) -> dict[str, dict]:
    """Per method: pairs and success (first proposals) on supports whose evaluated view hides
    (``hiding``) and on the rest."""
    def rate(success: pd.Series) -> float | None:
        return float(success.mean()) if len(success) else None

    first = trials[trials["proposal"].fillna(0) == 0]
    out = {}
    for method, g in first.groupby("method", sort=False):
        hid = g["support_id"].isin(hiding)
        out[method] = {"hiding_pairs": int(hid.sum()),
                       "hiding_success": rate(g.loc[hid, "success"]),
                       "other_pairs": int((~hid).sum()),
                       "other_success": rate(g.loc[~hid, "success"])}
    return out


def picture(rows: pd.DataFrame, root: Path, path: Path) -> bool:
    """Each hiding evaluated view (side, support x–z) beside the same support's view with the
    most band points, over the support's mesh vertices; False when there is none."""
    if rows.empty:
        return False
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(len(rows), 2, figsize=(10, 3.6 * len(rows)), squeeze=False)
    for ax_row, r in zip(axes, rows.itertuples()):
        points = read_npz(root / "render_views" / f"{r.support_id}.npz", RENDER_SPEC)["points"]
        mesh = read_obj(r.mesh)[0].vertices
        best = int(np.argmax(r.counts))
        for ax, view, what in ((ax_row[0], r.view, "evaluated"),
                               (ax_row[1], best, "most revealing")):
            ax.scatter(mesh[:, 0], mesh[:, 2], s=2, c="0.85", label="support mesh vertices")
            ax.scatter(points[view][:, 0], points[view][:, 2], s=2, c="tab:blue",
                       label="view's cloud")
            ax.axvspan(*BAND_M, color="tab:orange", alpha=0.15, label="band in front of the plate")
            ax.set_title(f"{r.support_id} ({r.difficulty}), view {view} ({what}): "
                         f"{int(r.counts[view])} points in the band", fontsize=9)
            ax.set_xlabel("x (m, out of the wall)")
            ax.set_ylabel("z (m)")
            ax.set_aspect("equal")
        ax_row[0].legend(fontsize=7, loc="upper right")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return True


def split_summary(d: pd.DataFrame) -> dict[str, dict]:
    """Per split: supports, views, hiding views, supports with one or more, and (splits of
    :data:`EVALUATED`) the supports whose evaluated view hides."""
    out = {}
    for split, g in d.groupby("split", sort=False):
        hiding = np.array([(c < MIN_POINTS).sum() for c in g["counts"]])
        evaluated = g.loc[g["view_count"] < MIN_POINTS, "support_id"].tolist()
        out[split] = {"supports": len(g), "views": int(sum(len(c) for c in g["counts"])),
                      "hiding_views": int(hiding.sum()),
                      "supports_with_hiding": int((hiding > 0).sum()),
                      "evaluated_hiding": evaluated if split in EVALUATED else None}
    return out


def report(splits: dict, methods: dict, has_picture: bool) -> str:
    lines = ["# Views that hide where a support leaves the wall", "",
             f"`tools/hidden_views.py`: a view *hides* when fewer than {MIN_POINTS} of its points "
             f"lie {1000 * (BAND_M[0] - PLATE_THICKNESS_M):.0f}–"
             f"{1000 * (BAND_M[1] - PLATE_THICKNESS_M):.0f} mm in front of the wall plate, where "
             "every generated support's strokes leave it. Regenerate: `.venv/bin/python -m "
             "tools.hidden_views` (after `make repro`).", "",
             "| split | supports | views | hiding views | supports with one or more "
             "| evaluated views hiding |",
             "|---|---|---|---|---|---|"]
    for split, v in splits.items():
        listed = v["evaluated_hiding"]
        share = 100 * v["hiding_views"] / v["views"]
        lines.append(f"| {split} | {v['supports']} | {v['views']} | {v['hiding_views']} "
                     f"({share:.1f} %) | {v['supports_with_hiding']} | "
                     f"{'–' if listed is None else ', '.join(listed) or 'none'} |")
    if methods:
        lines += ["", "One-SKT rows of `sim_eval` (first proposals) on the test supports whose "
                  "evaluated view hides, against the rest:", "",
                  "| method | pairs, hiding | success, hiding | pairs, rest | success, rest |",
                  "|---|---|---|---|---|"]
        for m, v in methods.items():
            fmt = (lambda x: "–" if x is None else f"{100 * x:.0f} %")
            lines.append(f"| `{m}` | {v['hiding_pairs']} | {fmt(v['hiding_success'])} | "
                         f"{v['other_pairs']} | {fmt(v['other_success'])} |")
    if has_picture:
        lines += ["", "![Each hiding evaluated test view beside its support's most revealing view]"
                  "(hidden_views.png)"]
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="tools/hidden_views.py", description=__doc__.splitlines()[0])
    ap.add_argument("--params", default="params.yaml", type=Path)
    ap.add_argument("--data-root", default="data", type=Path)
    ap.add_argument("--trials", type=Path,
                    help="sim_eval's trials (default: <data-root>/sim_eval/trials.parquet)")
    ap.add_argument("--out", default=Path("reports/sim_eval"), type=Path)
    args = ap.parse_args(argv)
    seed = load_params(args.params).common.seed
    d = survey(args.data_root, seed)
    splits = split_summary(d)
    hiding = set(splits["test"]["evaluated_hiding"]) if "test" in splits else set()
    trials_path = args.trials or args.data_root / "sim_eval" / "trials.parquet"
    methods = by_method(pd.read_parquet(trials_path), hiding) if trials_path.is_file() else {}
    args.out.mkdir(parents=True, exist_ok=True)
    has_picture = picture(d[d["support_id"].isin(hiding)], args.data_root,
                          args.out / "hidden_views.png")
    write_json_atomic(args.out / "hidden_views.json", {
        "band_m": list(BAND_M), "min_points": MIN_POINTS, "splits": splits, "methods": methods})
    text = report(splits, methods, has_picture)
    (args.out / "hidden_views.md").write_text(text)
    print(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
