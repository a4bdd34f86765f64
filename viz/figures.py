"""PNG figures for reports (matplotlib, Agg backend)."""

from dataclasses import dataclass, field
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from mpl_toolkits.mplot3d.art3d import Poly3DCollection  # noqa: E402

from skt_lib.io import atomic_path  # noqa: E402
from viz.rerun_log import AFFORDANCE_CMAP  # noqa: E402

_LIGHT = np.array([0.4, -0.6, 0.7]) / np.linalg.norm([0.4, -0.6, 0.7])


def _frame_3d(ax, points: np.ndarray, elev: float, azim: float, title: str) -> None:
    """Equal-aspect cube around ``points``, no axes, a view direction and a title."""
    lo, hi = points.min(0), points.max(0)
    c, half = (lo + hi) / 2, (hi - lo).max() / 2 + 1e-3
    ax.set(xlim=(c[0] - half, c[0] + half), ylim=(c[1] - half, c[1] + half),
           zlim=(c[2] - half, c[2] + half))
    ax.set_box_aspect((1, 1, 1))
    ax.view_init(elev=elev, azim=azim)
    ax.set_axis_off()
    ax.set_title(title, fontsize=8)


def save(fig, path: str | Path) -> None:
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", dpi=90, metadata={"Software": None})
    plt.close(fig)


@dataclass
class Panel:
    """One picture: meshes ``(vertices (V, 3), faces (F, 3), rgba)`` and optional red
    points ``(K, 3)`` and axis triads ``(origin (3,), rotation (3, 3))``, one frame."""

    title: str
    meshes: list = field(default_factory=list)
    points: np.ndarray | None = None
    frames: list = field(default_factory=list)
    lines: list = field(default_factory=list)  # polylines (M, 3), drawn in blue …
    line_colors: list = field(default_factory=list)  # … or in these colours, one per line


def mesh_gallery(panels: list[Panel], path: str | Path, ncols: int = 4, elev: float = 12.0,
                 azim: float = -70.0) -> None:
    """Shaded 3D views, one panel per subplot."""
    nrows = max(1, -(-len(panels) // ncols))
    fig = plt.figure(figsize=(3.0 * ncols, 3.0 * nrows))
    for k, panel in enumerate(panels):
        ax = fig.add_subplot(nrows, ncols, k + 1, projection="3d")
        for v, f, rgba in panel.meshes:
            tri = v[f]
            normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
            normal /= np.linalg.norm(normal, axis=1, keepdims=True) + 1e-12
            shade = 0.35 + 0.65 * np.clip(normal @ _LIGHT, 0, 1)
            colors = np.clip(np.outer(shade, rgba[:3]), 0, 1)
            ax.add_collection3d(Poly3DCollection(tri, facecolors=colors, edgecolors="none",
                                                 alpha=rgba[3]))
        allv = np.vstack([m[0] for m in panel.meshes] + [np.asarray(x).reshape(-1, 3) for x in panel.lines])
        if panel.points is not None:
            ax.scatter(*np.asarray(panel.points).T, color="red", s=18, depthshade=False)
        colours = list(panel.line_colors) + ["tab:blue"] * (len(panel.lines) - len(panel.line_colors))
        for line, colour in zip(panel.lines, colours):
            ax.plot(*np.asarray(line).T, color=colour, linewidth=1.0)
        for origin, rot in panel.frames:
            for axis, color in zip(rot.T, ("red", "green", "blue")):
                ax.quiver(*origin, *(0.03 * axis), color=color, linewidth=1.5)
        _frame_3d(ax, allv, elev, azim, panel.title)
    fig.tight_layout()
    save(fig, path)


def bar_chart(counts: dict[str, dict[str, int]], path: str | Path, title: str) -> None:
    """Grouped bars: counts[group][key]."""
    groups = list(counts)
    keys = sorted({k for g in counts.values() for k in g})
    fig, ax = plt.subplots(figsize=(max(5, 0.5 * len(keys) * len(groups)), 3.2))
    width = 0.8 / max(1, len(groups))
    x = np.arange(len(keys))
    for i, g in enumerate(groups):
        ax.bar(x + i * width, [counts[g].get(k, 0) for k in keys], width, label=g)
    ax.set_xticks(x + width * (len(groups) - 1) / 2, keys, rotation=30, ha="right", fontsize=8)
    ax.set_title(title)
    ax.legend(fontsize=8)
    fig.tight_layout()
    save(fig, path)


def histogram(values, path: str | Path, title: str, xlabel: str, bins: int = 30) -> None:
    fig, ax = plt.subplots(figsize=(5, 3))
    ax.hist(np.asarray(values), bins=bins, color="tab:blue")
    ax.set(title=title, xlabel=xlabel, ylabel="count")
    fig.tight_layout()
    save(fig, path)


def cloud_grid(items: list[tuple[str, np.ndarray, np.ndarray | None]], path: str | Path,
               ncols: int = 4, elev: float = 15.0, azim: float = -60.0) -> None:
    """3D scatter panels: (title, points (N, 3), values (N,) or None → one colour)."""
    nrows = max(1, -(-len(items) // ncols))
    fig = plt.figure(figsize=(3.0 * ncols, 3.0 * nrows))
    for k, (title, pts, values) in enumerate(items):
        ax = fig.add_subplot(nrows, ncols, k + 1, projection="3d")
        if values is None:
            ax.scatter(*pts.T, s=1.5, color="tab:blue", depthshade=False)
        else:
            ax.scatter(*pts.T, s=2.0, c=values, cmap=AFFORDANCE_CMAP, vmin=0, vmax=1,
                       depthshade=False)
        _frame_3d(ax, pts, elev, azim, title)
    fig.tight_layout()
    save(fig, path)


def scatter_2d(xy: np.ndarray, labels: np.ndarray, path: str | Path, title: str,
               highlight: np.ndarray | None = None) -> None:
    """Points coloured by label; ``highlight`` (K, 2) drawn as black crosses."""
    fig, ax = plt.subplots(figsize=(5, 4))
    sc = ax.scatter(xy[:, 0], xy[:, 1], c=labels, cmap="tab10", s=10)
    if highlight is not None:
        ax.scatter(highlight[:, 0], highlight[:, 1], marker="x", color="black", s=60)
    ax.legend(*sc.legend_elements(), fontsize=7, title="cluster")
    ax.set(title=title, xlabel="PC 1", ylabel="PC 2")
    fig.tight_layout()
    save(fig, path)


def agreement_scatter(xy: np.ndarray, support_family: np.ndarray, own_family: np.ndarray,
                      centres: np.ndarray, path: str | Path, title: str) -> None:
    """Every SKT at its PCA embedding, coloured by its *support's* family; an SKT whose own
    nearest centre is another family is ringed in red (it disagrees with its support)."""
    fig, ax = plt.subplots(figsize=(5, 4))
    sc = ax.scatter(xy[:, 0], xy[:, 1], c=support_family, cmap="tab10", s=10)
    off = support_family != own_family
    ax.scatter(xy[off, 0], xy[off, 1], facecolors="none", edgecolors="red", s=40, linewidths=0.8,
               label=f"disagrees with its support ({int(off.sum())}/{len(xy)})")
    ax.scatter(centres[:, 0], centres[:, 1], marker="x", color="black", s=60)
    handles, labels = sc.legend_elements()
    ax.legend(handles + ax.get_legend_handles_labels()[0][-1:],
              labels + ax.get_legend_handles_labels()[1][-1:], fontsize=7, title="support family")
    ax.set(title=title, xlabel="PC 1", ylabel="PC 2")
    fig.tight_layout()
    save(fig, path)


def curves(history: list[dict], keys: list[str], path: str | Path, title: str, ylabel: str) -> None:
    """Per-epoch curves of ``keys`` from a list of metric dicts."""
    fig, ax = plt.subplots(figsize=(5.5, 3.2))
    for key in keys:
        ax.plot([h[key] for h in history], label=key)
    ax.set(title=title, xlabel="epoch", ylabel=ylabel)
    ax.legend(fontsize=7)
    fig.tight_layout()
    save(fig, path)
