"""``skt predict``'s cleaning keeps the whole structure a view shows — the plate and an
arm seen apart from it — and drops clutter and flying pixels; no view of the tiny test
supports is refused, clean or with sensor-like noise."""

import numpy as np
import pytest

from skt_lib.cli.cloud_checks import check_support_cloud
from skt_lib.io import read_npz
from skt_lib.perception.pointcloud import clean_cloud
from skt_lib.perception.views import RENDER_SPEC


def _patch(rng, lo, hi, n) -> np.ndarray:
    return rng.uniform(lo, hi, size=(n, 3))


def test_an_arm_seen_apart_from_its_plate_is_kept_and_clutter_dropped():
    rng = np.random.default_rng(0)
    plate = _patch(rng, (0.0, -0.02, -0.03), (0.01, 0.02, 0.03), 600)
    tip = _patch(rng, (0.07, -0.005, 0.0), (0.09, 0.005, 0.02), 250)  # 6 cm past the plate
    clutter = _patch(rng, (0.35, 0.2, -0.05), (0.45, 0.3, 0.05), 120)  # a shelf 40 cm away
    flyers = rng.uniform((0.02, -0.05, -0.05), (0.06, 0.05, 0.05), size=(8, 3))
    out = clean_cloud(np.vstack([plate, tip, clutter, flyers]))
    kept = out.points
    assert (kept[:, 0] > 0.06).sum() >= 240  # the arm's end
    assert (kept[:, 0] < 0.011).sum() >= 580  # the plate
    assert not (kept[:, 0] > 0.3).any()  # no clutter
    assert out.counts["off_cluster"] >= 120
    check_support_cloud(kept)  # structure off the wall: not refused


@pytest.mark.parametrize("noisy", [False, True])
def test_no_test_view_is_refused(tiny_dataset, noisy):
    """Every view of every test support, as rendered and with depth-like noise (σ 1.5 mm, 3 %
    of points flung σ 2 cm): cleaned and checked without a refusal."""
    from skt_lib.io import read_table
    from skt_lib.schemas import SUPPORTS

    _, data, _ = tiny_dataset
    supports = read_table(data / "mesh_gen" / "supports.parquet", SUPPORTS)
    rng = np.random.default_rng(0)
    for sid in supports[supports["split"] == "test"]["support_id"]:
        views = read_npz(data / "render_views" / f"{sid}.npz", RENDER_SPEC)["points"]
        for k, view in enumerate(views.astype(np.float64)):
            if noisy:
                view = view + rng.normal(0.0, 0.0015, view.shape)
                flung = rng.choice(len(view), int(0.03 * len(view)), replace=False)
                view[flung] += rng.normal(0.0, 0.02, (len(flung), 3))
            check_support_cloud(clean_cloud(view, name=f"{sid} view {k}").points)
