"""``make paper``'s path (tools/paper.py) on a tiny paper-like preset: a run killed in the
middle of a stage, run again, ends with the outputs of an uninterrupted run (the session's
``tiny_dataset``, made by the stages' own ``main`` on the same parameters), and its reports
are collected with the commit and every stage's figures."""

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import yaml

from tests.conftest import TINY, assert_same_tree
from tools.paper import STAGES, merge, seed_segments, set_overrides, stage_totals, steps

pytestmark = pytest.mark.slow
ROOT = Path(__file__).resolve().parents[2]
EARLY = ("mesh_gen", "contact_sim", "rotation_extraction", "rrt_skts")


def _source_repo(dest: Path) -> Path:
    """A git repository whose one commit is this checkout's working tree (tracked and
    untracked, not ignored files): the code under test, committed, as make paper needs."""
    files = subprocess.run(["git", "ls-files", "-co", "--exclude-standard", "-z"], cwd=ROOT,
                           check=True, capture_output=True).stdout.decode().split("\0")
    for name in filter(None, files):
        if (ROOT / name).is_file():
            (dest / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / name, dest / name)
    (dest / ".venv").symlink_to(ROOT / ".venv")
    git = ["git", "-c", "user.name=test", "-c", "user.email=test@example.com"]
    for cmd in (["init", "-q"], ["add", "-A"], ["commit", "-q", "-m", "code under test"]):
        subprocess.run([*git, *cmd], cwd=dest, check=True)
    return dest


def _paper(src: Path, ws: Path, preset: Path, reports: Path, *extra: str) -> list[str]:
    return [sys.executable, "-m", "tools.paper", "--source", str(src), "--workspace", str(ws),
            "--preset", str(preset), "--reports", str(reports), *extra]


#: The tiny preset: ``TINY`` (params.yaml's further training supports off, as TINY has
#: none); after rrt_skts (compared with ``tiny_dataset``) fewer methods, for time.
PRESET = merge(TINY, {"train_baselines": {"models": ["vatmart"]},
                      "sim_eval": {"methods": ["oracle", "sctdn", "vatmart"]}})
PRESET["mesh_gen"] = {**PRESET["mesh_gen"], "n_extra_train_supports": 0}


@pytest.fixture(scope="module")
def paper_runs(tmp_path_factory):
    """(source, killed-and-resumed workspace, collected reports, items saved at the kill)."""
    tmp = tmp_path_factory.mktemp("paper")
    src = _source_repo(tmp / "src")
    preset = tmp / "tiny.yaml"
    preset.write_text(yaml.safe_dump(PRESET))
    killed, reports = tmp / "ws_killed", tmp / "reports"
    proc = subprocess.Popen(_paper(src, killed, preset, reports), cwd=ROOT,
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            start_new_session=True)
    work = killed / "data" / ".work" / "rrt_skts"
    try:
        deadline = time.monotonic() + 600
        while not list(work.glob("*/*.pkl")):
            assert proc.poll() is None, "make paper ended before rrt_skts saved an item: " + \
                proc.stderr.read().decode()[-2000:]
            assert time.monotonic() < deadline, "rrt_skts saved no item in 600 s"
            time.sleep(0.05)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    saved = len(list(work.glob("*/*.pkl")))
    assert not (killed / "data" / "rrt_skts" / "skts.parquet").exists(), "killed too late"
    subprocess.run(_paper(src, killed, preset, reports), cwd=ROOT, check=True,
                   stdout=subprocess.DEVNULL)
    return src, killed, reports, saved


def test_killed_paper_run_resumes_to_the_uninterrupted_outputs(paper_runs, tiny_dataset):
    src, killed, _, saved = paper_runs
    _, data, stage_reports = tiny_dataset
    assert saved >= 1
    for stage in EARLY:
        assert_same_tree(killed / "data" / stage, data / stage)
        assert (killed / "reports" / stage / "metrics.json").read_bytes() == \
            (stage_reports / stage / "metrics.json").read_bytes()
    # the run is the committed code with the preset over the committed params.yaml
    commit = subprocess.run(["git", "rev-parse", "HEAD"], cwd=src, check=True,
                            capture_output=True, text=True).stdout.strip()
    assert subprocess.run(["git", "rev-parse", "HEAD"], cwd=killed, capture_output=True,
                          text=True).stdout.strip() == commit
    params = yaml.safe_load((killed / "params.yaml").read_text())
    assert params == merge(yaml.safe_load((src / "params.yaml").read_text()), PRESET)
    # the default workspace of the source is untouched
    assert not (src / "data" / "mesh_gen").exists()


def test_reports_are_collected_with_commit_and_stage_figures(paper_runs):
    src, killed, reports, _ = paper_runs
    run = json.loads((reports / "run.json").read_text())
    stages = ["mesh_gen", "contact_sim", "rotation_extraction", "rrt_skts", "render_views",
              "affordance_maps", "clustering", "train", "train_baselines", "sim_eval"]
    assert list(run["stages"]) == stages
    for stage in stages:
        assert (reports / stage / "metrics.json").read_bytes() == \
            (killed / "reports" / stage / "metrics.json").read_bytes()
        assert run["stages"][stage]["wall_s"] > 0 and run["stages"][stage]["peak_rss_mb"] > 0
    # rrt_skts ran in two segments (killed, then resumed); the stages before it in one
    assert run["stages"]["rrt_skts"]["segments"] == 2
    assert run["stages"]["mesh_gen"]["segments"] == 1
    assert [s["exit_code"] != 0 for s in run["segments"]] == [True, False]
    assert run["commit"] == subprocess.run(["git", "rev-parse", "HEAD"], cwd=src, check=True,
                                           capture_output=True, text=True).stdout.strip()
    assert (reports / "dvc.lock").read_bytes() == (killed / "dvc.lock").read_bytes()
    assert "| **pipeline** |" in (reports / "README.md").read_text()
    # the clone's copies of the default's other reports are not the paper run's
    for other in ("camera", "seeds", "bench", "tests", "paper", "train/diagnostics.json",
                  "sim_eval/hidden_views.md"):
        assert not (reports / other).exists(), other
    # run again on an up-to-date workspace: nothing reruns, the same reports
    before = (reports / "sim_eval" / "metrics.json").read_bytes()
    subprocess.run(_paper(src, killed, killed.parent / "tiny.yaml", reports, "--collect-only"),
                   cwd=ROOT, check=True, stdout=subprocess.DEVNULL)
    assert (reports / "sim_eval" / "metrics.json").read_bytes() == before


def test_overrides_name_unknown_keys_and_parse_values():
    assert set_overrides(["compute.backend=dask", "rrt_skts.n_skts_per_support=50"]) == \
        {"compute": {"backend": "dask"}, "rrt_skts": {"n_skts_per_support": 50}}
    assert merge({"a": {"b": 1, "c": 2}}, {"a": {"b": 3}}) == {"a": {"b": 3, "c": 2}}
    with pytest.raises(SystemExit, match="a.x: not a key"):
        merge({"a": {"b": 1}}, {"a": {"x": 3}})
    with pytest.raises(SystemExit, match="expected section.key=value"):
        set_overrides(["compute.backend"])


def test_stage_totals_count_a_stages_last_completed_run_across_commits():
    def seg(commit, exit_code, **stages):
        return {"kind": "pipeline", "commit": commit, "exit_code": exit_code, "stages": {
            name: {"wall_s": w, "cpu_s": 2 * w, "peak_rss_mb": 10 * w}
            for name, w in stages.items()}}
    segments = [
        seg("c0", 0, rrt_skts=100.0),                    # an earlier complete run: superseded
        seg("c0", None, mesh_gen=1.0, rrt_skts=7.0),      # mesh_gen done, rrt_skts killed
        {**seg("c1", 0, train=50.0), "kind": "seeds"},   # not pipeline time
        seg("c1", 0, rrt_skts=5.0, train=3.0),            # resumed on a later commit
    ]
    totals = stage_totals(segments)
    assert list(totals) == ["mesh_gen", "rrt_skts", "train"]  # pipeline order
    assert totals["rrt_skts"] == {"wall_s": 12.0, "cpu_s": 24.0, "peak_rss_mb": 70.0,
                                  "segments": 2, "commits": ["c0", "c1"]}
    assert totals["mesh_gen"]["commits"] == ["c0"] and totals["train"]["segments"] == 1
    # a stage still running when its segment was killed has no completed run yet
    assert "train" not in stage_totals(segments[:2] + [seg("c1", None, train=3.0)])
    # saved segments' keys are sorted: the order they ran in is their first sighting (DVC may
    # run render_views, which needs only mesh_gen, before rrt_skts)
    ran = seg("c2", None, rrt_skts=30.0, render_views=20.0)
    ran["stages"]["render_views"]["first_s"], ran["stages"]["rrt_skts"]["first_s"] = 5.0, 40.0
    totals = stage_totals([ran])
    assert "render_views" in totals and "rrt_skts" not in totals


def test_seeds_are_made_before_the_one_sim_eval_that_merges_them():
    assert steps("dvc", "py", None, 1) == [(["dvc", "repro"], "pipeline")]
    assert steps("dvc", "py", "rrt_skts", 3) == [(["dvc", "repro", "rrt_skts"], "pipeline")]
    (models, _), (sweep, kind), (last, _) = steps("dvc", "py", None, 3)
    assert models[:2] == ["dvc", "repro"] and sorted(models[2:]) == sorted(
        s for s in STAGES if s != "sim_eval")
    assert sweep == ["py", "-m", "tools.seed_sweep", "--seeds", "3"] and kind == "seeds"
    assert last == ["dvc", "repro"]

    def seg(kind, *stages):
        return {"kind": kind, "stages": {name: {} for name in stages}}
    made = seg("seeds")
    # the old order (sim_eval, the seeds, sim_eval again) and the new one count the seeds
    assert seed_segments([seg("pipeline", "train", "sim_eval"), made, seg("seeds")]) == \
        [made, seg("seeds")]
    assert seed_segments([seg("pipeline", "train"), made, seg("pipeline", "sim_eval")]) == [made]
    # a model stage rerun after them makes them stale
    assert seed_segments([made, seg("pipeline", "train", "sim_eval")]) == []
    # a seed step resumed (a pipeline segment that ran nothing between its parts) counts both;
    # a later seed step (trials only, after a sim_eval change) is counted alone
    a1, a2, b = seg("seeds"), seg("seeds"), seg("seeds")
    a1["wall_s"], a2["wall_s"], b["wall_s"] = 1.0, 2.0, 3.0
    first = [seg("pipeline", "train"), a1, seg("pipeline"), a2, seg("pipeline", "sim_eval")]
    assert seed_segments(first) == [a1, a2]
    again = [*first, seg("pipeline"), b, seg("pipeline", "sim_eval")]
    assert [s["wall_s"] for s in seed_segments(again)] == [3.0]


def test_only_seeds_the_run_merged_are_collected(tmp_path):
    from tools.paper import merged_seeds

    ws = tmp_path
    seeds = ws / "reports" / "seeds" / "seed_runs.json"
    metrics = ws / "reports" / "sim_eval" / "metrics.json"
    seeds.parent.mkdir(parents=True)
    metrics.parent.mkdir(parents=True)
    seeds.write_text("{}")
    git = ["git", "-c", "user.name=test", "-c", "user.email=test@example.com"]
    for cmd in (["init", "-q"], ["add", "-A"], ["commit", "-q", "-m", "checked out"]):
        subprocess.run([*git, *cmd], cwd=ws, check=True)
    metrics.write_text(json.dumps({"seeds": {"status": "ok"}}))
    assert not merged_seeds(ws)  # the default's seeds, as checked out: not the run's
    seeds.write_text('{"seeds": {}}')  # written by the run's seed step ...
    assert merged_seeds(ws)  # ... and merged by its sim_eval
    metrics.write_text(json.dumps({"seeds": {"status": "stale", "reason": "other inputs"}}))
    assert not merged_seeds(ws)  # an earlier seed step's, on other models
    metrics.write_text(json.dumps({}))
    assert not merged_seeds(ws)


def test_a_dvc_lock_is_removed_only_when_it_names_processes_all_gone(tmp_path, capsys):
    from tools.paper import clear_stale_rwlock

    lock = tmp_path / ".dvc" / "tmp" / "rwlock"
    lock.parent.mkdir(parents=True)
    lock.write_text(json.dumps({"read": {}, "write": {}}))  # what an ended run leaves
    clear_stale_rwlock(tmp_path)
    assert lock.exists() and not capsys.readouterr().out
    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()
    held = {"write": {"data/x": {"pid": os.getpid(), "cmd": "dvc repro"}}}
    lock.write_text(json.dumps(held))  # a live run's
    clear_stale_rwlock(tmp_path)
    assert lock.exists()
    lock.write_text(json.dumps({"read": {"data/x": [{"pid": gone.pid, "cmd": "dvc repro"}]}}))
    clear_stale_rwlock(tmp_path)  # a killed run's
    assert not lock.exists() and "left by a killed run" in capsys.readouterr().out
