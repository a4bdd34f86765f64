"""contact_sim and render_views: an item that fails is counted by reason, never dropped
silently, and never shifts another item's result (stubbed work, no data on disk)."""

import contextlib
import json
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest

from skt_lib.config import ComputeParams
from skt_lib.errors import DataError, ItemFailure
from stages import contact_sim, render_views
from viz import contact_sim_report, render_views_report

COMPUTE = ComputeParams(backend="local", n_workers=1)


class _NoItems:
    def __init__(self, *a, **k):
        pass

    def next(self, *a, **k):
        pass


def _quiet(monkeypatch, module, *names):
    """Replace viz/Rerun helpers with no-ops: these tests are about the counts."""
    monkeypatch.setattr(module, "recording", lambda *a, **k: contextlib.nullcontext(None))
    monkeypatch.setattr(module, "ItemTimeline", _NoItems)
    for name in names:
        monkeypatch.setattr(module, name, lambda *a, **k: None)


def _args(tmp_path):
    params = tmp_path / "params.yaml"  # read only to fingerprint resumable work (load_params is faked)
    params.write_text("{}\n")
    return ["--params", str(params), "--data-root", str(tmp_path / "data"),
            "--data-dir", str(tmp_path / "out"), "--reports-dir", str(tmp_path / "rep")]


def test_render_views_counts_failed_supports(monkeypatch, tmp_path):
    supports = pd.DataFrame({"support_id": ["s0", "s1", "s2", "s3"], "mesh_path": ["m"] * 4,
                             "difficulty": ["easy", "normal", "hard", "very_hard"], "family": ["peg"] * 4})
    p = SimpleNamespace(n_azimuth=1, n_elevation=1, n_points=8, noise_std_m=0.0,
                        sensor_severity=0.0, sensor_views_severity=0.0, width=4, height=3,
                        fov_deg=40.0,
                        azimuth_deg=[0, 0], elevation_deg=[0, 0], distance_m=0.3)

    def fake_render(task):
        if task.support_id == "s1":
            raise ItemFailure("nothing visible", "not_visible")
        return {"support_id": task.support_id, "render_s": [0.001], "n_rerendered": 0,
                "n_padded": int(task.support_id == "s3"),
                "on_surface_rate": {"s0": 1.0, "s2": 0.5, "s3": 0.0}[task.support_id]}

    monkeypatch.setattr(render_views, "load_sections", lambda *_, **__: SimpleNamespace(
        render_views=p, common=SimpleNamespace(seed=1), compute=COMPUTE))
    monkeypatch.setattr(render_views, "read_table", lambda *a: supports)
    monkeypatch.setattr(render_views, "render_support", fake_render)
    monkeypatch.setattr(render_views_report, "read_npz", lambda *a: {
        "points": np.zeros((1, 8, 3), np.float32), "cameras": np.tile(np.eye(4), (1, 1, 1))})
    _quiet(monkeypatch, render_views_report, "log_points", "log_camera", "log_mesh", "cloud_grid")
    monkeypatch.setattr(render_views_report, "read_obj",
                        lambda path: [SimpleNamespace(vertices=None, faces=None)])
    assert render_views.main(_args(tmp_path)) == 0
    m = json.loads((tmp_path / "rep" / "metrics.json").read_text())
    assert (m["n_supports"], m["n_rendered"], m["n_failed"]) == (4, 3, 1)
    assert m["failures_by_reason"] == {"not_visible": 1} and m["failed_supports"] == ["s1"]
    # per-support values stay with their support: mean over s0, s2, s3 only
    assert m["on_surface_rate"] == pytest.approx(0.5) and m["n_views_padded"] == 1
    assert "3 of 4 supports rendered" in (tmp_path / "rep" / "report.md").read_text()

    monkeypatch.setattr(render_views, "render_support",
                        lambda t: (_ for _ in ()).throw(ItemFailure("x", "not_visible")))
    with pytest.raises(DataError, match="no support rendered"):
        render_views.main(_args(tmp_path))


def test_contact_sim_counts_items_that_raise(monkeypatch, tmp_path):
    objects = pd.DataFrame({"object_id": ["ref", "o1", "o2"], "urdf_path": ["u"] * 3,
                            "aperture_clearance_m": [0.02] * 3,
                            "is_reference": [True, False, False], "mesh_path": ["m"] * 3,
                            "category": ["reference", "mug", "tool"]})
    supports = pd.DataFrame({"support_id": ["s0", "s1", "s2"], "urdf_path": ["u"] * 3,
                             "arm_centreline": [np.zeros((2, 3))] * 3,
                             "hang_point": [np.zeros(3)] * 3, "radius_m": [0.004] * 3,
                             "difficulty": ["easy", "easy", "hard"], "mesh_path": ["m"] * 3})
    perturb = SimpleNamespace(accel_m_s2=4.0, steps_per_direction=1, settle_steps=1)
    p = SimpleNamespace(rod_radius_m=0.005, n_drops=2, drop_steps=1, perturb=perturb, dt=0.01)
    written = {}

    def fake_sim(task):
        if task.item_id in ("o2", "s1"):
            raise ItemFailure(f"{task.item_id} exploded", "unstable_contact")
        ok = task.item_id != "s2"
        return {"item_id": task.item_id, "kind": task.kind, "object_id": task.object_id,
                "support_id": task.support_id, "ok": ok,
                "failure_reason": "" if ok else "dropped", "n_success": 2 * ok, "n_attempts": 2,
                "hang_position": [0.0, 0.0, 0.0], "hang_quat": [0.0, 0.0, 0.0, 1.0],
                "contact_support": [0.0, 0.0, 0.0], "goal_rank": 0 if ok else -1,
                "goal_shift_m": 0.0 if ok else float("nan")}

    monkeypatch.setattr(contact_sim, "load_sections", lambda *_, **__: SimpleNamespace(
        contact_sim=p, common=SimpleNamespace(seed=1), compute=COMPUTE,
        sim_eval=SimpleNamespace(linear_damping=0.04, angular_damping=0.04,
                                 settle_linear_damping=1.0, settle_angular_damping=5.0)))
    monkeypatch.setattr(contact_sim, "read_table",
                        lambda path, schema: objects if "objects" in str(path) else supports)
    monkeypatch.setattr(contact_sim, "simulate_hangs", fake_sim)
    monkeypatch.setattr(contact_sim, "write_table", lambda path, rows, schema:
                        written.setdefault("rows", rows))
    monkeypatch.setattr(contact_sim, "read_obj", lambda *a: [SimpleNamespace(
        vertices=np.zeros((3, 3)), faces=np.array([[0, 1, 2]]))])
    _quiet(monkeypatch, contact_sim_report, "log_mesh", "log_points", "mesh_gallery")
    assert contact_sim.main(_args(tmp_path)) == 0
    m = json.loads((tmp_path / "rep" / "metrics.json").read_text())
    assert [r["item_id"] for r in written["rows"]] == ["ref", "o1", "s0", "s2"]
    assert (m["n_supports"], m["n_supports_ok"], m["n_objects"], m["n_objects_ok"]) == (3, 1, 2, 1)
    assert m["support_success_rate"] == pytest.approx(1 / 3) and m["reference_ok"] is True
    assert m["supports_ok_by_difficulty"] == {"easy": 1, "normal": 0, "hard": 0, "very_hard": 0}
    assert m["failures_by_reason"] == {"dropped": 1, "unstable_contact": 2}
    assert m["n_items_raised"] == 2 and m["items_raised"] == {"o2": "unstable_contact",
                                                              "s1": "unstable_contact"}
    assert m["drop_success_rate"] == pytest.approx(6 / 8)
    text = (tmp_path / "rep" / "report.md").read_text()
    assert "`s1` (reference_on_support): unstable_contact (raised" in text
