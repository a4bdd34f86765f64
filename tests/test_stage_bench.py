"""bench writes bench.json afresh: a key from an older run does not survive."""

import json
from types import SimpleNamespace

import pytest

from stages import bench


def test_bench_json_is_written_fresh(monkeypatch, tmp_path):
    out = tmp_path / "bench.json"
    out.write_text(json.dumps({"stale_key": 1.0, "rrt_plan_s_median": 99.0}))
    monkeypatch.setattr(bench, "load_params", lambda _: SimpleNamespace(
        compute=SimpleNamespace(n_workers=2), common=SimpleNamespace(seed=0),
        sim_eval=SimpleNamespace(n_proposals=10, flow_contacts=3, flow_samples=30)))
    monkeypatch.setattr(bench, "rrt_bench", lambda *a: {"rrt_plan_s_median": 1.0})
    monkeypatch.setattr(bench, "sctdn_bench", lambda *a: {"sctdn_inference_ms_median": 2.0})
    monkeypatch.setattr(bench, "flow_bench", lambda *a: {"skt_flow_inference_ms_median": 7.0})
    monkeypatch.setattr(bench, "sim_bench", lambda *a: {"sim_trials_per_min": 3.0})
    monkeypatch.setattr(bench, "cli_bench", lambda *a: {"cli_predict_ms_median": 5.0})
    monkeypatch.setattr(bench, "render_bench", lambda *a: {"render_ms_per_view_median": 4.0})
    monkeypatch.setattr(bench, "bench_dense_imports", lambda *a: {"import_dense_s_median": 6.0})
    assert bench.main(["--out", str(out), "--data-root", str(tmp_path)]) == 0
    got = json.loads(out.read_text())
    assert set(got) == {"rrt_plan_s_median", "sctdn_inference_ms_median",
                        "skt_flow_inference_ms_median", "sim_trials_per_min",
                        "render_ms_per_view_median", "cli_predict_ms_median",
                        "import_dense_s_median", "machine", "parts_commit"}
    assert got["rrt_plan_s_median"] == 1.0
    assert set(got["parts_commit"]) == set(bench.PARTS)


def test_bench_parts_replace_their_own_keys_and_keep_the_others(monkeypatch, tmp_path):
    """--parts sim: the sim keys are measured again (a stale one goes), every other part's
    keys stay as they were, and parts_commit names the commit of each part's figures."""
    out = tmp_path / "bench.json"
    out.write_text(json.dumps({"rrt_plan_s_median": 99.0, "sim_trials_per_min": 1.0,
                               "sim_stale": 7, "parts_commit": {"rrt": "abc", "sim": "abc"}}))
    monkeypatch.setattr(bench, "load_params", lambda _: SimpleNamespace(
        compute=SimpleNamespace(n_workers=2)))
    monkeypatch.setattr(bench, "_commit", lambda: "def")
    monkeypatch.setattr(bench, "sim_bench", lambda *a: {"sim_trials_per_min": 3.0})
    for name in ("rrt_bench", "sctdn_bench", "flow_bench", "cli_bench", "render_bench",
                 "bench_dense_imports"):
        monkeypatch.setattr(bench, name, lambda *a: pytest.fail("only sim was asked for"))
    assert bench.main(["--out", str(out), "--data-root", str(tmp_path), "--parts", "sim"]) == 0
    got = json.loads(out.read_text())
    assert got["rrt_plan_s_median"] == 99.0 and got["sim_trials_per_min"] == 3.0
    assert "sim_stale" not in got
    assert got["parts_commit"]["rrt"] == "abc" and got["parts_commit"]["sim"] == "def"
    assert got["parts_commit"]["render"] == "unknown"  # the old file had no record of it


def test_planner_bench_times_both_planners_on_the_same_supports(tiny_dataset):
    """rrt_bench on the tiny set: the one-tree planner and the per-SKT reference plan the same
    supports at the asked SKT count, the speed-up is their rates' ratio, and every bench key
    it writes has a row in the docs (tests/test_docs.py checks the committed file)."""
    from skt_lib.config.params_file import load_params
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


def test_sim_bench_leaves_out_trials_whose_set_up_found_no_grasp(tiny_dataset):
    """sim_bench on the tiny set with a recording runner: a trial the default executor could
    not set up (ik_failed, no grasp) is timed by no executor, every other trial by all three
    (the same trials, in the same order), and a reference verdict the default executor does
    not repeat is reported as a disagreement, and one it repeats as a failure for another
    reason disagrees on the reason only."""
    from collections import Counter

    from skt_lib import speed
    from skt_lib.config.params_file import load_params
    from skt_lib.sim.execute import EXECUTORS
    from tools.docs_results import BENCH_ROWS, BENCH_SAMPLE

    params_path, data, _ = tiny_dataset
    calls = []

    def runner(fn, items, compute, desc):
        calls.append((desc, [t.settings.executor for t in items], [t.trial_id for t in items]))
        ids = [t.trial_id for t in items]
        rows = [{"trial_id": i, "grasp": "g", "failure_reason": ""} for i in ids]
        if "screen" in desc:
            rows[0] |= {"grasp": "", "failure_reason": "ik_failed"}  # no grasp: left out
            rows[1] |= {"failure_reason": "ik_failed"}  # a grasp, lost on the way: kept
        if desc.endswith("reference"):
            rows[-1] |= {"failure_reason": "dropped"}
            rows[-2] |= {"failure_reason": "collided_before_hang"}
        if desc.endswith(("fallen_exit", "rest_exit")):
            rows[-2] |= {"failure_reason": "dropped"}  # a failure for another reason
        return [{"row": r} for r in rows], Counter(), []

    got = speed.sim_bench(load_params(params_path), data, 1, runner)
    (screen, _, all_ids), *timed = calls
    assert screen.endswith("set-up screen") and len(all_ids) >= 3
    assert [d.rsplit(", ", 1)[1] for d, _, _ in timed] == list(EXECUTORS)
    for desc, executors, ids in timed:
        assert ids == all_ids[1:] and set(executors) == {desc.rsplit(", ", 1)[1]}
    assert got["sim_bench_trials"] == len(all_ids) - 1
    assert got["sim_bench_setup_failures_excluded"] == 1
    assert got["sim_bench_failures_reference"] == 2
    assert got["sim_verdict_disagreements"] == [
        f"{all_ids[-2]}: collided_before_hang → dropped", f"{all_ids[-1]}: dropped → success"]
    assert got["sim_verdict_agreement"] == 1.0 - 2 / (len(all_ids) - 1)
    # the failure for another reason is still a failure: only the drop that hung disagrees
    assert got["sim_success_agreement"] == 1.0 - 1 / (len(all_ids) - 1)
    assert set(got) <= set(BENCH_ROWS) | set(BENCH_SAMPLE)
