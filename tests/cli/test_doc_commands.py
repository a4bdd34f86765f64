"""The commands the README and docs/cli.md show, run as written, with the outcome they promise.

Every line of their ``bash`` blocks is either run here (:data:`RUN`) or named in
:data:`ELSEWHERE` with where it is checked, so a command added to or changed in the docs fails
these tests until a test runs it. The commands run in a folder laid out as a user's checkout
after ``make repro``: ``params.yaml``, ``data/`` (the tiny pipeline's stages, linked),
``.venv`` (this one, linked), and the files the commands name (``hook.ply`` …) made from the
tiny pipeline's data. The README's five-minute example runs on the committed parameters and
the committed preset's objects, so what it prints here is what it prints after ``make repro``.
"""

import json
import os
import re
import shlex
import shutil
import sys
from pathlib import Path

import numpy as np
import pybullet_data
import pytest
import yaml

from skt_lib.cli import example_hooks
from skt_lib.geometry.se3 import invert
from tests.cli.conftest import ROOT, STAGES, camera_cloud, run_skt, save_ply

DOCS = (ROOT / "README.md", ROOT / "docs" / "cli.md")
FENCE = re.compile(r"^```bash\n(.*?)^```", re.M | re.S)
PYBULLET_MUG = Path(pybullet_data.getDataPath()) / "objects" / "mug.obj"

#: the lines of the README's five-minute example, in order (run by the five-minute test)
FIVE_MINUTES = (
    ".venv/bin/python -m skt_lib.cli.example_hooks /tmp/hooks",
    ".venv/bin/skt import-support /tmp/hooks/coat_hook.stl",
    ".venv/bin/skt hang --support coat_hook --object "
    ".venv/lib/python3.11/site-packages/pybullet_data/objects/mug.obj --method oracle "
    "--rrd coat.rrd",
    ".venv/bin/rerun coat.rrd",
)
#: the "your own cloud, object and hook" commands (README and docs/cli.md), run in order
OWN_FILES = (
    "skt predict hook.ply -o skt.json --rrd skt.rrd",
    "skt predict hook.ply --model data/train -o sctdn.json",
    "skt predict scan.npy --units mm --frame cam_to_support.json",
    "skt predict raw.ply --camera --up 0 -1 0 -o skt.json",
    "skt predict raw.ply --camera --up 0 -1 0",
    "skt import-object my_mug.obj --name my_mug",
    "skt import-support my_hook.stl --units mm",
    "skt hang --support support_00008 --object my_mug --rrd hang.rrd",
    "skt hang --support support_00008 --object my_mug --method oracle --rrd hang.rrd",
    "skt hang --support support_00008 --object object_mug_000 --method vatmart --proposals 10",
)
RUN = (*FIVE_MINUTES, *OWN_FILES)
ELSEWHERE = {
    "make repro": "CI's pipeline tests (tests/test_resume.py, the tiny pipeline) and every "
                  "committed report",
    "make test": "CI itself (.ci/run)",
}


def doc_commands(path: Path) -> list[str]:
    """The commands of ``path``'s ``bash`` blocks: continuation lines joined, comments and
    blank lines dropped, whitespace collapsed."""
    out = []
    for block in FENCE.findall(path.read_text()):
        for line in block.replace("\\\n", " ").splitlines():
            line = " ".join(line.split("#", 1)[0].split())
            if line:
                out.append(line)
    return out


def test_every_documented_command_is_run_by_a_test():
    shown = {c for doc in DOCS for c in doc_commands(doc)}
    assert shown, "no bash blocks found"
    assert sorted(shown - set(RUN) - set(ELSEWHERE)) == []  # shown, run nowhere
    assert sorted(set(RUN) - shown) == []  # run here, shown nowhere: a stale entry


def _skt_args(command: str, subst: dict[str, str]) -> list[str]:
    words = [subst.get(w, w) for w in shlex.split(command)]
    assert words[0] in ("skt", ".venv/bin/skt"), command
    return words[1:]


@pytest.fixture
def checkout(tmp_path, tiny_dataset, monkeypatch):
    """A folder laid out as a user's checkout after ``make repro`` (tiny pipeline), the
    working directory while the test runs."""
    params, data, _ = tiny_dataset
    (tmp_path / "data").mkdir()
    for stage in STAGES:
        (tmp_path / "data" / stage).symlink_to(data / stage, target_is_directory=True)
    # the committed planner: the tiny one cannot thread a hook's bend
    tiny, committed = yaml.safe_load(params.read_text()), yaml.safe_load(
        (ROOT / "params.yaml").read_text())
    tiny["rrt_skts"] = committed["rrt_skts"]
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(tiny))
    (tmp_path / ".venv").symlink_to(Path(sys.prefix), target_is_directory=True)
    monkeypatch.chdir(tmp_path)
    return tmp_path


@pytest.mark.slow
def test_your_own_files_commands_run_as_documented(capsys, checkout, view):
    """hook.ply: a rendered view (support frame); scan.npy: the same view in a camera frame,
    in millimetres, with its pose; raw.ply: a depth camera's raw cloud, the wall in view, up
    along the camera's −y; my_mug.obj: pybullet_data's mug; my_hook.stl: the example coat
    hook in millimetres."""
    data = checkout / "data"
    save_ply(checkout / "hook.ply", view)
    cam_to_support = np.eye(4)
    cam_to_support[:3, :3] = [[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]]
    cam_to_support[:3, 3] = [0.3, 0.01, -0.02]
    np.save(checkout / "scan.npy", 1000 * ((view - cam_to_support[:3, 3]) @ cam_to_support[:3, :3]))
    (checkout / "cam_to_support.json").write_text(json.dumps(cam_to_support.tolist()))
    raw, pose = camera_cloud(data, view=3)
    up = pose[:3, :3].T @ [0.0, 0.0, 1.0]  # the true up, camera frame
    assert np.degrees(np.arccos(up @ [0.0, -1.0, 0.0])) < 30.0  # the docs' --up 0 -1 0 holds
    save_ply(checkout / "raw.ply", raw)
    shutil.copy(PYBULLET_MUG, checkout / "my_mug.obj")
    hook = example_hooks.coat_hook()
    hook.apply_scale(1000.0)
    hook.export(checkout / "my_hook.stl")
    for command in OWN_FILES:
        rc, out, err = run_skt(capsys, *_skt_args(command, {}))
        assert rc == 0, f"{command}: {err}"
        words = shlex.split(command)
        if words[1] == "predict":
            written = words[words.index("-o") + 1] if "-o" in words else "skt.json"
            doc = json.loads(Path(written).read_text())
            assert doc["warnings"] == [], (command, doc["warnings"])  # looks like a training view
            assert len(doc["waypoints"]) == doc["T"]
            # the default model is skt_flow's; --model data/train is SCTDN's
            assert doc["model_kind"] == ("sctdn" if "data/train" in words else "skt_flow")
            assert out.startswith(f"{written}: SKT of {doc['T']} waypoints"), out
            if "--camera" in words:  # the frame found from the wall: within 5 mm and 2°
                err_t = doc["camera"]["camera_to_support"] @ invert(pose)
                assert np.linalg.norm(err_t[:3, 3]) <= 0.005
                cos = np.clip((np.trace(err_t[:3, :3]) - 1) / 2, -1.0, 1.0)
                assert np.degrees(np.arccos(cos)) <= 2.0
            else:
                assert "camera" not in doc
        elif words[1] == "import-object":
            assert (data / "user" / "objects" / "my_mug" / "object.json").exists(), out
        elif words[1] == "import-support":
            rec = json.loads((data / "user" / "supports" / "my_hook" / "support.json").read_text())
            assert rec["skts"], out
        else:  # hang: one verdict line, for the pair asked
            support, obj = words[words.index("--support") + 1], words[words.index("--object") + 1]
            method = words[words.index("--method") + 1] if "--method" in words else "skt_flow"
            assert re.search(rf"^{method} {support} × {obj}: (success|failed: \w+)", out,
                             re.M), out
            if "--proposals" in words:
                assert re.search(r"proposal \d+ of 10", out), out
        if "--rrd" in words:
            assert Path(words[words.index("--rrd") + 1]).stat().st_size > 0
    for name in ("skt.json", "skt.rrd", "hang.rrd"):
        assert (checkout / name).exists()


@pytest.mark.slow
def test_the_five_minute_example_prints_what_the_readme_says(capsys, tmp_path, monkeypatch):
    """The README's walk-through on the committed parameters: its objects and their keypoints
    are the committed preset's (``mesh_gen`` draws each object from its own seed and
    ``contact_sim`` hangs it on the rod, whatever the support count, so a 12-support run makes
    the same reference object), the hook and mug as the README makes them. It prints what the
    README says, and the recording shows the hang."""
    from stages import contact_sim, mesh_gen, rotation_extraction
    from viz.recording_query import item_labels

    committed = yaml.safe_load((ROOT / "params.yaml").read_text())
    small = {**committed, "mesh_gen": {**committed["mesh_gen"], "n_supports": 12,
                                        "n_extra_train_supports": 0, "n_val_per_level": 1,
                                        "n_test_per_level": 1},
             "compute": {**committed["compute"], "n_workers": 1}}
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(small))
    for stage in (mesh_gen, contact_sim, rotation_extraction):  # what the import needs
        name = stage.__name__.rsplit(".", 1)[-1]
        assert stage.main(["--params", str(tmp_path / "params.yaml"),
                           "--data-root", str(tmp_path / "data"),
                           "--data-dir", str(tmp_path / "data" / name),
                           "--reports-dir", str(tmp_path / "reports" / name),
                           "--log-dir", str(tmp_path / "logs")]) == 0
    (tmp_path / ".venv").symlink_to(Path(sys.prefix), target_is_directory=True)
    monkeypatch.chdir(tmp_path)
    hooks = str(tmp_path / "hooks")
    example, import_support, hang, viewer = FIVE_MINUTES
    assert example_hooks.main([shlex.split(example)[-1].replace("/tmp/hooks", hooks)]) == 0
    rc, out, err = run_skt(capsys, *_skt_args(import_support, {"/tmp/hooks/coat_hook.stl":
                                                              f"{hooks}/coat_hook.stl"}))
    assert rc == 0, err
    # "the level it measured from the mesh, the arm it hangs on … how many of its SKTs reach"
    assert re.search(r"imported coat_hook \(arm 0 of 2, \w+, .*\d+/\d+ SKTs reach the hang\)",
                     out), out
    rc, out, err = run_skt(capsys, *_skt_args(hang, {}))
    assert rc == 0, err
    readme = (ROOT / "README.md").read_text()
    assert "`skt hang` prints the\nverdict (here `success`" in readme
    assert "oracle coat_hook × mug: success" in out, out
    # `rerun coat.rrd` opens the trial: its label says the same
    assert shlex.split(viewer) == [".venv/bin/rerun", "coat.rrd"]
    assert os.access(tmp_path / ".venv" / "bin" / "rerun", os.X_OK)
    labels = item_labels(tmp_path / "coat.rrd", "trial")
    assert list(labels) == [0] and labels[0].startswith("# oracle/coat_hook/mug: success\n")
