"""The report figures draw from plain arrays and write PNGs."""

import numpy as np

from skt_lib.geometry.convex import box
from viz.figures import Panel, cloud_grid, mesh_gallery
from viz.report import Report


def test_figures_and_report(tmp_path):
    b = box([0, 0, 0], [0.01, 0.02, 0.03])
    rep = Report("demo", tmp_path)
    mesh_gallery([Panel("box", [(b.vertices, b.faces, (1, 0, 0, 1))], points=np.zeros((1, 3)),
                        frames=[(np.zeros(3), np.eye(3))], lines=[np.zeros((2, 3))])],
                 rep.figure("g.png", "gallery"))
    pts = np.random.default_rng(0).normal(size=(50, 3))
    cloud_grid([("c", pts, None), ("v", pts, np.linspace(0, 1, 50))], rep.figure("c.png", "clouds"))
    rep.table(["a", "b"], [[1, 0.5]])
    text = rep.write().read_text()
    assert "![gallery](g.png)" in text and "| 1 | 0.5 |" in text
    for name in ("g.png", "c.png"):
        assert (tmp_path / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
