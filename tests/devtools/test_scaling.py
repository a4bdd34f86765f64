"""tools.scaling: the process-tree monitor, the power-law fit and the figure."""

import json
import sys

import pytest
import yaml

from tools import scaling

# a stage that holds 300 MB itself while a worker holds 200 MB more
STAGE = ("import subprocess, sys, time\n"
         "b = bytearray(300 * 2**20); b[::4096] = b'x' * len(b[::4096])\n"
         "w = subprocess.Popen([sys.executable, '-c', 'b = bytearray(200 * 2**20); "
         "b[::4096] = bytes(len(b[::4096])); import time; time.sleep(2)'])\n"
         "time.sleep(2.5); w.wait()\n")


def test_stage_of_reads_python_dash_m():
    assert scaling.stage_of(["/v/bin/python", "-m", "stages.rrt_skts"]) == "rrt_skts"
    assert scaling.stage_of(["python", "-c", "x", "-m", "stages.train"]) == "train"
    assert scaling.stage_of(["python", "-m", "tools.scaling"]) is None
    assert scaling.stage_of(["dvc", "repro", "stages.train"]) is None


def test_monitor_sums_a_stage_and_its_workers(tmp_path):
    rc, wall, stages = scaling.run_monitored(
        [sys.executable, "-c", STAGE, "-m", "stages.toy"], tmp_path)
    assert rc == 0 and set(stages) == {"toy"}
    toy = stages["toy"]
    assert 500 <= toy["peak_rss_mb"] < 700  # both processes counted, once each
    assert 2.0 <= toy["wall_s"] <= wall + scaling.POLL_S
    assert toy["cpu_s"] > 0


def test_fit_recovers_a_power_law():
    a, b = scaling.fit([60, 120, 240], [3.0 * n**1.5 for n in (60, 120, 240)])
    assert a == pytest.approx(3.0) and b == pytest.approx(1.5)


def test_plot_only_redraws_from_the_json(tmp_path):
    runs = [{"n_supports": n, "commit": "x", "wall_s": 10.0 * n,
             "stages": {"mesh_gen": {"wall_s": n / 10, "cpu_s": n / 5, "peak_rss_mb": 100.0 + n},
                        "train": {"wall_s": n, "cpu_s": 2 * n, "peak_rss_mb": 900.0}}}
            for n in (60, 120, 240)]
    (tmp_path / "scaling.json").write_text(json.dumps({"runs": runs}))
    assert scaling.main(["--plot-only", "--out", str(tmp_path)]) == 0
    data = json.loads((tmp_path / "scaling.json").read_text())
    assert data["peak_rss_mb"]["mesh_gen"] == 340.0 and data["peak_rss_mb"]["train"] == 900.0
    assert (tmp_path / "scaling.png").stat().st_size > 10_000


def test_extrapolation_and_tables():
    def stages(n):
        return {"mesh_gen": {"wall_s": 0.5 * n, "cpu_s": n, "peak_rss_mb": 100.0},
                "rrt_skts": {"wall_s": 2.0 * n**1.2, "cpu_s": 4 * n, "peak_rss_mb": 800.0},
                "sim_eval": {"wall_s": 600.0 + n / 60, "cpu_s": 1200.0, "peak_rss_mb": 900.0}}
    data = {"stages": ["mesh_gen", "rrt_skts", "sim_eval"], "skts_per_support": 4,
            "n_test_supports": 20, "machine": "2 cores", "peak_rss_mb": {
                "mesh_gen": 100.0, "rrt_skts": 800.0, "sim_eval": 900.0},
            "runs": [{"n_supports": n, "commit": "abc", "wall_s": 2000.0, "stages": stages(n)}
                     for n in (60, 120, 240)]}
    paper = scaling.extrapolate(data)
    assert paper["mesh_gen"] == pytest.approx(0.5 * 472)
    assert paper["rrt_skts"] == pytest.approx(2.0 * 472**1.2 * 50 / 4)
    assert paper["sim_eval"] == pytest.approx((600.0 + 420 / 180) * 3)  # fixed test set
    table = scaling.table(data)
    assert "| `rrt_skts` | " in table and "| 1.20 | 800 |" in table
    assert "extrapolat" in table
    summary = scaling.presets_summary(data)
    params = yaml.safe_load((scaling.ROOT / "params.yaml").read_text())
    default = params["mesh_gen"]["n_supports"]  # a run at the committed count is the default
    label = "embedded default" if default == 120 else "default, resized"
    assert f"| {label} | 120 | 480 | 33 min (measured at abc) |" in summary
    assert "fresh clone" not in summary
    data["fresh_repro"] = {"commit": "def", "wall_s": 1700.0, "setup_s": 90.0, "stages": {},
                           "git_status_clean": True}
    planned = scaling.skts_planned(params)  # an older record: the committed sizes
    assert (f"| embedded default, fresh clone + `make repro` (set-up included) | {default} | "
            f"{planned:,} | 28.3 min (measured at def) |") in scaling.presets_summary(data)
    data["fresh_repro"].update(n_supports=120, skts_planned=560)  # the sizes it measured
    assert ("| embedded default, fresh clone + `make repro` (set-up included) | 120 | 560 | "
            "28.3 min (measured at def) |") in scaling.presets_summary(data)
    assert f"≈ {sum(paper.values()) / 3600:.1f} h (**extrapolated**; `rrt_skts`" in summary
    assert scaling.table({"runs": []}).startswith("No sweep over support counts is recorded")


def test_fresh_clones_and_runs_make_repro_with_set_up_timed(tmp_path, monkeypatch):
    """``--fresh``: a plain clone of the repo at ``ROOT`` and ``make repro`` in it, under the
    monitor; the set-up is the time before the first stage, and a dirty tree is reported."""
    import subprocess

    repo = tmp_path / "repo"
    repo.mkdir()
    (repo / "Makefile").write_text(
        "repro:\n\tsleep 1.5\n"  # the "set-up"
        f"\t{sys.executable} -c 'import time; time.sleep(1.2)' -m stages.toy\n"
        "\ttouch untracked.txt\n")
    (repo / "params.yaml").write_text(yaml.safe_dump({  # the sizes the clone runs
        "mesh_gen": {"n_supports": 30, "n_test_per_level": 1},
        "rrt_skts": {"n_skts_per_support": 2, "n_skts_per_test_support": 3}}))
    git = ["git", "-c", "user.name=t", "-c", "user.email=t@t"]
    subprocess.run(["git", "init", "-q", str(repo)], check=True)
    subprocess.run([*git, "add", "Makefile", "params.yaml"], cwd=repo, check=True)
    subprocess.run([*git, "commit", "-qm", "toy"], cwd=repo, check=True)
    monkeypatch.setattr(scaling, "ROOT", repo)
    out = tmp_path / "out"
    out.mkdir()
    (out / "scaling.json").write_text(json.dumps({"runs": []}))
    f = scaling.fresh_repro(tmp_path / "work")
    assert set(f["stages"]) == {"toy"} and 1.0 <= f["stages"]["toy"]["wall_s"] <= 2.5
    assert 1.4 <= f["setup_s"] <= f["wall_s"] - 1.0
    assert f["wall_s"] >= 2.7 and f["git_status_clean"] is False
    assert len(f["commit"]) >= 7
    assert (f["n_supports"], f["skts_planned"]) == (30, 26 * 2 + 4 * 3)
    text = scaling.fresh_summary({"machine": "2 cores", "fresh_repro": f})
    assert f"commit {f['commit']}" in text and "`toy`" in text and "**not** clean" in text
    assert f["git_status"] == ["?? untracked.txt"] and "(`untracked.txt`)" in text
    assert scaling.fresh_summary({}).startswith("Not measured")


def test_skts_planned_counts_test_supports_at_their_own_rate():
    params = {"rrt_skts": {"n_skts_per_support": 4, "n_skts_per_test_support": 8},
              "mesh_gen": {"n_supports": 120, "n_test_per_level": 5}}
    assert scaling.skts_planned(params) == 100 * 4 + 20 * 8
    params["mesh_gen"]["n_extra_train_supports"] = 30  # all training: 4 SKTs each
    assert scaling.skts_planned(params) == 130 * 4 + 20 * 8
    assert scaling.total_supports(params) == 150
    del params["rrt_skts"]["n_skts_per_test_support"]  # params from before the split count
    assert scaling.skts_planned(params) == 150 * 4


def test_paper_run_is_recorded_measured_and_stale_counts_forgotten(tmp_path):
    """``--paper-run``: make paper's own figures become the paper row (measured, not
    extrapolated) and the per-stage table beside the fresh default; ``--forget`` drops
    counts; the plot then compares the two presets."""
    paper = tmp_path / "paper"
    paper.mkdir()
    params = yaml.safe_load((scaling.ROOT / "params.yaml").read_text())
    params["mesh_gen"].update(n_supports=472, n_extra_train_supports=0, n_test_per_level=15)
    params["rrt_skts"].update(n_skts_per_support=50, n_skts_per_test_support=50)
    (paper / "params.yaml").write_text(yaml.safe_dump(params))
    stages = {"rrt_skts": {"wall_s": 3600.0, "cpu_s": 7000.0, "peak_rss_mb": 1600.0,
                           "segments": 2, "commits": ["a"]},
              "sim_eval": {"wall_s": 1800.0, "cpu_s": 3500.0, "peak_rss_mb": 2500.0,
                           "segments": 1, "commits": ["a"]}}
    (paper / "run.json").write_text(json.dumps({
        "commit": "abcdef1234", "machine": "x86_64, 2 cores, 24 GiB", "stages": stages,
        "pipeline_wall_s": 5400.0, "seeds_wall_s": 900.0, "segments": []}))
    runs = [{"n_supports": n, "commit": "old", "wall_s": 10.0 * n, "stages": {
        "rrt_skts": {"wall_s": n, "cpu_s": n, "peak_rss_mb": 900.0}}} for n in (60, 120)]
    (tmp_path / "scaling.json").write_text(json.dumps({
        "runs": runs, "fresh_repro": {"commit": "def", "wall_s": 1700.0, "setup_s": 60.0,
                                      "git_status_clean": True, "n_supports": 200,
                                      "skts_planned": 880, "stages": {
                                          "rrt_skts": {"wall_s": 480.0, "cpu_s": 900.0,
                                                       "peak_rss_mb": 900.0}}}}))
    assert scaling.main(["--paper-run", str(paper / "run.json"), "--forget", "60", "120",
                         "--out", str(tmp_path)]) == 0
    data = json.loads((tmp_path / "scaling.json").read_text())
    assert data["runs"] == [] and "peak_rss_mb" not in data
    p = data["paper_run"]
    assert (p["commit"], p["n_supports"], p["wall_s"]) == ("abcdef1", 472, 5400.0)
    assert p["skts_planned"] == 472 * 50 and p["stages"]["rrt_skts"]["cpu_s"] == 7000.0
    summary = scaling.presets_summary(data)
    assert ("| paper (`make paper`, one training seed) | 472 | 23,600 | 1.5 h (measured at "
            "abcdef1; `rrt_skts` 60 min of it) |") in summary
    assert ("| paper, seed step (two more training seeds) | 472 | – | 15 min (measured at "
            "abcdef1) |") in summary
    assert "extrapolated" not in summary and "resized" not in summary
    table = scaling.paper_table(data)
    assert "| `rrt_skts` | 8.0 | 60.0 | 116.7 | 1600 |" in table
    assert "| `sim_eval` | – | 30.0 | 58.3 | 2500 |" in table
    assert "seed step" in table and "15.0 min" in table
    assert (tmp_path / "scaling.png").stat().st_size > 10_000
    # an --out folder that does not exist yet is made (a fresh run once lost 43 min to it)
    assert scaling.main(["--paper-run", str(paper / "run.json"), "--out",
                         str(tmp_path / "new" / "out")]) == 0
    assert json.loads((tmp_path / "new" / "out" / "scaling.json").read_text())["paper_run"]
