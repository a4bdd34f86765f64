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
    monkeypatch.setattr(bench, "bench_dense_imports", lambda *a: {"import_dense_s_median": 6.0})
    assert bench.main(["--out", str(out), "--data-root", str(tmp_path)]) == 0
    got = json.loads(out.read_text())
    assert set(got) == {"rrt_plan_s_median", "sctdn_inference_ms_median", "sim_trials_per_min",
                        "render_ms_per_view_median", "cli_predict_ms_median",
                        "import_dense_s_median", "machine"}
    assert got["rrt_plan_s_median"] == 1.0


def test_planner_bench_times_both_planners_on_the_same_supports(tiny_dataset):
    """rrt_bench on the tiny set: the one-tree planner and the per-SKT reference plan the same
    supports at the asked SKT count, the speed-up is their rates' ratio, and every bench key
    it writes has a row in the docs (tests/test_docs.py checks the committed file)."""
    from skt_lib.config import load_params
    from tools.docs_results import BENCH_ROWS, BENCH_SAMPLE

    params_path, data, _ = tiny_dataset
    got = bench.rrt_bench(load_params(params_path), data, per_level=1, n_skts=3)
    assert got["rrt_bench_supports"] == 4 and got["rrt_bench_skts_per_support"] == 3
    assert 0 < got["rrt_bench_skts"] <= 12 and 0 < got["rrt_bench_skts_reference"] <= 12
    assert got["rrt_speedup_vs_reference_planner"] == (got["rrt_skts_per_min"]
                                                       / got["rrt_skts_per_min_reference"])
    for key in ("rrt_diversity_mm", "rrt_diversity_mm_reference"):
        assert set(got[key]) == {"easy", "normal", "hard", "very_hard"}
        assert all(v is None or v >= 0 for v in got[key].values())
    # the one-tree planner's SKTs of a support start at distinct points: they differ
    assert any(v for v in got["rrt_diversity_mm"].values())
    assert set(got) <= set(BENCH_ROWS) | set(BENCH_SAMPLE)
