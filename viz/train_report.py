"""The train stage's validation breakdown: figures per family and per level, and one
validation support per family drawn with its ground truth, template and prediction."""

from pathlib import Path

import numpy as np

from skt_lib.geometry.export import read_obj
from skt_lib.io import read_table
from skt_lib.learning.train import summarise
from skt_lib.schemas import SUPPORTS
from viz.figures import Panel, mesh_gallery
from viz.report import Report


def validation_breakdown(report: Report, items, per: dict, root: Path) -> None:
    """Validation figures per family and per level (best model's predictions ``per`` on the
    (support, view) ``items``), and one validation support per family drawn with its ground
    truth, the aligned template and the prediction."""
    rows = []
    for key, name in ((lambda s: f"family {s.family}", "family"), (lambda s: s.level, "level")):
        groups = sorted({key(s) for s, _ in items})
        for g in groups:
            m = np.array([key(s) == g for s, _ in items])
            sub = summarise({k: v[m] for k, v in per.items()})
            rows.append([name, g, int(m.sum()), sub["val_traj_l2_mm"], sub["val_template_only_l2_mm"],
                         sub["val_cls_acc"], sub["val_contact_within_1cm_rate"]])
    report.heading("Validation by family and by level (best epoch)")
    report.table(["by", "group", "views", "SCTDN mm", "template-only mm", "cls acc",
                  "contact ≤ 1 cm"], rows)
    supports = read_table(root / "mesh_gen" / "supports.parquet", SUPPORTS).set_index("support_id")
    panels, seen = [], set()
    for i, (s, v) in enumerate(items):
        if s.family in seen:
            continue
        seen.add(s.family)
        (mesh,) = read_obj(root / "mesh_gen" / supports.loc[s.support_id, "mesh_path"])
        panels.append(Panel(f"{s.support_id} (family {s.family}, {s.level}, view {v}): "
                            f"{per['traj_mm'][i]:.0f} mm",
                            [(mesh.vertices, mesh.faces, (0.35, 0.22, 0.12, 1.0))],
                            points=np.stack([per["contact_m"][i], s.contact]),
                            lines=[*s.skts, per["aligned_m"][i], per["trajectory_m"][i]],
                            line_colors=["0.6"] * len(s.skts) + ["tab:orange", "tab:blue"]))
    mesh_gallery(panels, report.figure("val_predictions.png", "One validation support per family: "
                 "ground-truth SKTs (grey), aligned template (orange), SCTDN prediction (blue); red: "
                 "predicted and true contact"))
