"""bench writes bench.json afresh: a key from an older run does not survive."""

import json
from types import SimpleNamespace

from stages import bench


def test_bench_json_is_written_fresh(monkeypatch, tmp_path):
    out = tmp_path / "bench.json"
    out.write_text(json.dumps({"stale_key": 1.0, "rrt_plan_s_median": 99.0}))
    monkeypatch.setattr(bench, "load_params", lambda _: SimpleNamespace(
        compute=SimpleNamespace(n_workers=2)))
    monkeypatch.setattr(bench, "rrt_bench", lambda *a: {"rrt_plan_s_median": 1.0})
    monkeypatch.setattr(bench, "sctdn_bench", lambda *a: {"sctdn_inference_ms_median": 2.0})
    monkeypatch.setattr(bench, "sim_bench", lambda *a: {"sim_trials_per_min": 3.0})
    monkeypatch.setattr(bench, "cli_bench", lambda *a: {"cli_predict_ms_median": 5.0})
    monkeypatch.setattr(bench, "render_bench", lambda *a: {"render_ms_per_view_median": 4.0})
    assert bench.main(["--out", str(out), "--data-root", str(tmp_path)]) == 0
    got = json.loads(out.read_text())
    assert set(got) == {"rrt_plan_s_median", "sctdn_inference_ms_median", "sim_trials_per_min",
                        "render_ms_per_view_median", "cli_predict_ms_median", "machine"}
    assert got["rrt_plan_s_median"] == 1.0
