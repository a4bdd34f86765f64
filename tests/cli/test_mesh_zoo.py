"""The mesh zoo (:mod:`skt_lib.cli.mesh_zoo`) through ``skt import-support`` / ``import-object``,
each case in a process of its own: no case ends the process abnormally (exit codes 0 or 2
only), the "import" cases import (the known misses named, with their reason), every
"refuse" case gets one ``ERROR:`` line and leaves its data root as it was, dense meshes are
simplified within a stated distance, and a killed import leaves nothing half-written."""

import json
import os
import signal
import subprocess
import sys
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from skt_lib.cli.mesh_zoo import DENSE_FACES, cases, linked_root, run_case
from skt_lib.geometry.simplify import MAX_FACES
from tests.cli.conftest import tree_state

#: "import" cases that do not import today, with what their error says: the pigtail's 330°
#: curl defeats the threading planner (4 of 4 SKT attempts ``no_path``): along the curl's back
#: the reference ring's body, kept outside the curl by an SKT's frames, meets the wall
#: (``python -m tools.route_room``, docs/cli.md).
KNOWN_MISSES = {
    "pigtail": "no SKT reaches the hang",
}
#: The simplified surface stays this close to the dense one (m, measured Hausdorff).
MAX_HAUSDORFF_M = 5e-4

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def zoo(tiny_dataset, tmp_path_factory):
    """Every case imported (two at a time) with the committed params on the tiny pipeline's
    data: {name: (outcome, data root, tree before)}."""
    _, data, _ = tiny_dataset
    base = tmp_path_factory.mktemp("zoo")
    # the committed params, as a user imports with them (the tiny preset's fewer drops and
    # coarser planner are for the pipeline's speed); the data is the tiny pipeline's
    zoo_params = Path("params.yaml").resolve()
    meshes = base / "meshes"
    meshes.mkdir()

    def one(case):
        root = linked_root(base, case.name, data)
        before = tree_state(root)
        return case.name, (run_case(case, meshes, root, zoo_params, timeout_s=900), root, before)

    with ThreadPoolExecutor(2) as pool:
        out = dict(pool.map(one, cases()))
    for name, (o, _, _) in out.items():
        print(f"{name:22s} {o.case.expect:7s} rc={o.returncode} {o.seconds:5.1f} s "
              f"{(o.errors or (o.stdout.strip(),))[-1][:160]}")
    return out


def _record(root: Path, case) -> dict:
    return json.loads((root / "user" / f"{case.kind}s" / case.name / f"{case.kind}.json")
                      .read_text())


def test_no_case_ends_the_process_abnormally(zoo):
    assert {name: o.returncode for name, (o, _, _) in zoo.items()
            if o.returncode not in (0, 2)} == {}


def test_every_refusal_is_one_error_line_and_writes_nothing(zoo):
    refused = {name: v for name, v in zoo.items() if v[0].case.expect == "refuse"}
    assert len(refused) >= 7
    for name, (o, root, before) in refused.items():
        assert o.returncode == 2, name
        assert len(o.errors) == 1 and o.case.reason in o.errors[0], (name, o.errors)
        assert o.stdout == "", name
        assert tree_state(root) == before and not (root / "user").exists(), name


def test_the_import_cases_import_but_the_named_misses(zoo):
    wanted = {name: v for name, v in zoo.items() if v[0].case.expect == "import"}
    assert len(wanted) >= 30
    missed = {name: o.errors for name, (o, _, _) in wanted.items() if o.returncode != 0}
    print(f"imported {len(wanted) - len(missed)}/{len(wanted)}; missed: {missed}")
    assert set(missed) <= set(KNOWN_MISSES), missed
    for name, errors in missed.items():
        assert len(errors) == 1 and KNOWN_MISSES[name] in errors[0], (name, errors)
    for name, (o, root, _) in wanted.items():
        if o.returncode == 0:
            assert o.errors == () and (root / "user").is_dir(), name


def test_dense_meshes_are_simplified_within_a_stated_distance(zoo):
    dense = {name: v for name, v in zoo.items() if v[0].case.dense and v[0].returncode == 0}
    assert sum(name.endswith("_250k") for name in dense) >= 4
    for name, (o, root, _) in dense.items():
        rec = _record(root, o.case)
        if name.endswith("_250k"):
            assert rec["n_faces_source"] >= DENSE_FACES, name
        assert rec["n_faces"] <= MAX_FACES < rec["n_faces_source"], name
        assert rec["simplified_by"] != "none", name
        assert 0.0 < rec["simplify_hausdorff_m"] <= MAX_HAUSDORFF_M, (name, rec)


def test_units_frames_and_prongs_come_out_as_the_user_meant(zoo):
    plain = _record(zoo["j_hook_coarse"][1], zoo["j_hook_coarse"][0].case)
    for name in ("j_hook_mm", "j_hook_rotated"):
        o, root, _ = zoo[name]
        assert o.returncode == 0, o.errors
        rec = _record(root, o.case)
        assert rec["difficulty"] == plain["difficulty"], name
        assert abs(rec["blocking_height_m"] - plain["blocking_height_m"]) < 0.002, name
    for name in ("fork_2", "fork_3", "rack"):
        o, root, _ = zoo[name]
        assert o.returncode == 0, o.errors
        rec = _record(root, o.case)
        assert rec["n_arms"] >= 2, name
        assert f"arm {rec['arm']} of {rec['n_arms']}" in o.stdout, name


def _descendants(pid: int) -> list[int]:
    out, todo = [], [pid]
    while todo:
        p = todo.pop()
        try:
            kids = [int(c) for c in Path(f"/proc/{p}/task/{p}/children").read_text().split()]
        except FileNotFoundError:
            continue
        out += kids
        todo += kids
    return out


def _cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
    except FileNotFoundError:
        return ""


def test_a_killed_import_leaves_nothing_half_written(tiny_dataset, tmp_path):
    """SIGKILL while the convex decomposition runs: no import folder, no staging folder.
    (That the child dies with its parent is asserted where it can be forced: the cup hook's
    decomposition may end on its own within the wait, tests/geometry/test_decompose.py.)"""
    _, data, _ = tiny_dataset
    root = linked_root(tmp_path, "root", data)
    case = next(c for c in cases() if c.name == "cup_hook")
    mesh = case.write(tmp_path)
    proc = subprocess.Popen([sys.executable, "-m", "skt_lib.cli.main", "import-support",
                             str(mesh), "--data-root", str(root)],
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    child = []
    deadline = time.monotonic() + 120
    while not child and time.monotonic() < deadline and proc.poll() is None:
        child = [p for p in _descendants(proc.pid) if "skt_lib.isolated" in _cmdline(p)]
        time.sleep(0.02)
    assert child, "the decomposition's child process never showed"
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    for _ in range(250):
        if all(not _cmdline(p) for p in child):
            break
        time.sleep(0.02)
    assert all(not _cmdline(p) for p in child), "the decomposition outlived the import"
    assert not (root / "user").exists()
