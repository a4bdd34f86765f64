"""Resumable stages: a stage killed mid-run (SIGKILL of its process group), rerun, redoes
only the unfinished items and ends with the bytes of an uninterrupted run."""

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from skt_lib.resume import ItemStore, stage_fingerprint
from tests.conftest import assert_same_tree

pytestmark = pytest.mark.slow
ROOT = Path(__file__).resolve().parents[1]


def _kill_after_first_items(stage: str, params, data_root, out: Path, rep: Path) -> int:
    """Run ``stage`` in its own process group; SIGKILL the group once at least one item is
    saved and before the stage ends. Returns the number of items saved at the kill."""
    work = out.parent / ".work" / stage
    proc = subprocess.Popen(
        [sys.executable, "-m", f"stages.{stage}", "--params", str(params), "--data-root",
         str(data_root), "--data-dir", str(out), "--reports-dir", str(rep),
         "--log-dir", str(out.parent / "logs")],
        cwd=ROOT, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, start_new_session=True)
    try:
        deadline = time.monotonic() + 240
        while not list(work.glob("*/*.pkl")):
            assert proc.poll() is None, "stage ended before any item was saved: " + \
                proc.stderr.read().decode()[-2000:]
            assert time.monotonic() < deadline, "no item finished in 240 s"
            time.sleep(0.05)
    finally:
        os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
    assert not (out / f"{stage}.rrd").exists(), "the stage finished before the kill"
    return len(list(work.glob("*/*.pkl")))


def _resume_counting(monkeypatch, module, argv) -> list:
    """Rerun the stage in-process, recording the items it computes (every newly finished
    item is saved once; items read back are not)."""
    saved = []
    real = ItemStore.save

    def save(self, key, result):
        saved.append(key)
        real(self, key, result)

    monkeypatch.setattr(ItemStore, "save", save)
    assert module.main(argv) == 0
    return saved


@pytest.mark.parametrize("stage", ["rrt_skts", "sim_eval"])
def test_killed_stage_resumes_and_matches_uninterrupted_run(stage, tiny_dataset, tiny_evaluated,
                                                           tmp_path, monkeypatch):
    params, data, reports = tiny_dataset
    if stage == "rrt_skts":
        from stages import rrt_skts as module
        ref_out, ref_rep = data / "rrt_skts", reports / "rrt_skts"
    else:
        from stages import sim_eval as module
        ref_out, ref_rep = tiny_evaluated[2], tiny_evaluated[3]
    out, rep = tmp_path / "data" / stage, tmp_path / "reports" / stage
    work = out.parent / ".work" / stage
    saved = _kill_after_first_items(stage, params, data, out, rep)
    before = {p.stem for p in work.glob("*/*.pkl")}
    argv = ["--params", str(params), "--data-root", str(data), "--data-dir", str(out),
            "--reports-dir", str(rep), "--log-dir", str(tmp_path / "logs")]
    calls = _resume_counting(monkeypatch, module, argv)
    ref = json.loads((ref_rep / "metrics.json").read_text())
    n_items = ref["n_supports"] if stage == "rrt_skts" else \
        sum(v["n_sim_runs"] for v in ref.values() if isinstance(v, dict) and "n_sim_runs" in v)
    # the resumed run computed exactly the items the killed one had not saved
    assert 1 <= saved < n_items
    assert len(calls) == n_items - saved and len(before) == saved
    assert before.isdisjoint(calls) and len(set(calls)) == len(calls)
    assert_same_tree(out, ref_out)
    # no wall clock in what is tracked: the reports are the same bytes
    for name in ("metrics.json", "report.md"):
        assert (rep / name).read_bytes() == (ref_rep / name).read_bytes(), name
    assert not (tmp_path / "data" / ".work").exists(), "work folder left behind"


def test_fingerprint_changes_with_params_and_inputs(tiny_dataset, tmp_path, write_params,
                                                    tiny_dict):
    params, data, _ = tiny_dataset
    base = stage_fingerprint("rrt_skts", params, data)
    assert stage_fingerprint("rrt_skts", params, data) == base
    tiny_dict["rrt_skts"]["shortcut_steps"] += 1
    assert stage_fingerprint("rrt_skts", write_params(tiny_dict), data) != base
    tiny_dict["rrt_skts"]["shortcut_steps"] -= 1
    tiny_dict["render_views"]["n_points"] += 1  # not an rrt_skts param: same fingerprint
    assert stage_fingerprint("rrt_skts", write_params(tiny_dict), data) == base
    # an upstream artifact changes: another fingerprint
    copy = tmp_path / "data"
    subprocess.run(["cp", "-r", str(data), str(copy)], check=True)
    assert stage_fingerprint("rrt_skts", params, copy) == base
    kp = copy / "rotation_extraction" / "keypoints.parquet"
    kp.write_bytes(kp.read_bytes() + b"\0")
    assert stage_fingerprint("rrt_skts", params, copy) != base


def test_stale_work_is_dropped_and_damaged_files_recomputed(tmp_path):
    store = ItemStore(tmp_path / ".work" / "s" / "abc")
    store.save("k1", {"x": 1})
    assert store.load("k1") == {"x": 1}
    (store.folder / "k2.pkl").write_bytes(b"not a pickle")
    assert store.load("k2") is ItemStore.MISSING and store.load("k3") is ItemStore.MISSING
    store.finish()
    assert not (tmp_path / ".work").exists()


def test_item_keys_are_the_same_in_another_process(tiny_params):
    """Keys must not depend on hash randomisation (pickled sets do)."""
    from dataclasses import dataclass

    code = ("import sys; from tests.conftest import TINY; from skt_lib.config.params_file import parse_params;"
            "from skt_lib.resume import ItemStore; p = parse_params(TINY);"
            "print(ItemStore.key(print, (p.rrt_skts, {'b', 'a', 'c'})))")
    keys = {subprocess.run([sys.executable, "-c", code], cwd=ROOT, capture_output=True, text=True,
                           env={**os.environ, "PYTHONHASHSEED": str(seed)}, check=True).stdout
            for seed in (1, 2, 3)}
    assert len(keys) == 1
    assert ItemStore.key(print, (tiny_params.rrt_skts, {"a", "b", "c"})) == keys.pop().strip()
    changed = tiny_params.rrt_skts.model_copy(update={"shortcut_steps": 11})
    assert ItemStore.key(print, (changed, {"a", "b", "c"})) != \
        ItemStore.key(print, (tiny_params.rrt_skts, {"a", "b", "c"}))

    @dataclass
    class Odd:
        x: object

    with pytest.raises(TypeError, match="cannot key"):
        ItemStore.key(print, Odd(object()))
