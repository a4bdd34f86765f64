"""The bad-input table of docs/cli.md, one row per test: each gives one ``ERROR:`` line naming the
file or argument, exit code 2, no traceback, no output file, and leaves the data root as it was."""

import json
import shutil
import subprocess
import sys

import numpy as np
import pytest

from tests.cli.conftest import EASY_SUPPORT, OBJECT, run_skt, save_ply, tree_state


def _predict(cloud, d, *extra):
    return ["predict", cloud, "--model", d / "train", "-o", "OUT/skt.json", *extra]


def _hang(d, params, support=EASY_SUPPORT, obj=OBJECT, method="oracle", *extra):
    return ["hang", "--support", support, "--object", obj, "--method", method,
            "--params", params, "--data-root", d, *extra]


def _write(path, data: bytes):
    path.write_bytes(data)
    return path


def _bare_wall():
    """A scan of the wall alone: 3000 points on x = 0 (1 mm noise), 30 × 30 cm."""
    rng = np.random.default_rng(4)
    return np.c_[rng.normal(0, 0.001, 3000), rng.uniform(-0.15, 0.15, (3000, 2))]


def _camera_wall():
    """A depth camera's cloud of a bare wall 40 cm in front of it (camera frame, 1 mm noise)."""
    rng = np.random.default_rng(5)
    return np.c_[rng.uniform(-0.15, 0.15, (20000, 2)), 0.4 + rng.normal(0, 0.001, 20000)]


def _ball():
    """No plane anywhere: 5000 points in a 5 cm Gaussian ball 40 cm in front of a camera."""
    return np.random.default_rng(6).normal(0, 0.05, (5000, 3)) + [0.0, 0.0, 0.4]


def _corrupt(t, model_dir, name):
    """A copy of ``model_dir`` in ``t`` with its config ``name.json`` and a corrupt
    ``name.pt``."""
    m = t / "model"
    m.mkdir()
    shutil.copy(model_dir / f"{name}.json", m / f"{name}.json")
    _write(m / f"{name}.pt", b"PK\x03\x04 not a checkpoint")
    return m


# (row name, builder (tmp, data root, view, params) -> (args, what the message must name))
ROWS = {
    "missing file": lambda t, d, v, p: (_predict(t / "nope.ply", d), "nope.ply: no such"),
    "empty file": lambda t, d, v, p: (_predict(_write(t / "e.ply", b""), d), "e.ply: empty file"),
    "unknown cloud format": lambda t, d, v, p: (_predict(_write(t / "c.csv", b"1,2,3\n"), d),
                                                "c.csv: unknown point-cloud format"),
    "not a PLY": lambda t, d, v, p: (_predict(_write(t / "x.ply", b"hello\n"), d), "x.ply: no points"),
    "corrupt npy": lambda t, d, v, p: (_predict(_write(t / "x.npy", b"\x93NUMPY garbage"), d),
                                       "x.npy: not a readable"),
    "npz without points": lambda t, d, v, p: (
        _predict(_npz(t / "x.npz", a=v, b=v), d), "x.npz: 2 arrays and none named 'points'"),
    "text that is not numbers": lambda t, d, v, p: (
        _predict(_write(t / "x.xyz", b"x y z\nfoo bar baz\n"), d), "x.xyz: not a readable"),
    "2-column array": lambda t, d, v, p: (_predict(_npy(t / "x.npy", v[:, :2]), d),
                                          "x.npy: expected an (N, 3) array"),
    "NaN rows (too few finite)": lambda t, d, v, p: (
        _predict(_npy(t / "x.npy", np.where(np.arange(len(v))[:, None] < 950, np.nan, v)), d),
        "50 finite points, need at least 100"),
    "10 points": lambda t, d, v, p: (_predict(_npy(t / "x.npy", v[:10]), d),
                                     "10 finite points, need at least 100"),
    "millimetre cloud": lambda t, d, v, p: (_predict(_npy(t / "x.npy", 1000 * v), d),
                                            "millimetres"),
    "metres said to be mm": lambda t, d, v, p: (_predict(_npy(t / "x.npy", v), d, "--units", "mm"),
                                                "was it in metres already"),
    "all views of a render_views NPZ": lambda t, d, v, p: (
        _predict(_npz(t / "x.npz", points=np.stack([v, v])), d),
        "x.npz: expected an (N, 3) array of x, y, z, got shape (2, 1000, 3)"),
    "fewer distinct points than the network samples": lambda t, d, v, p: (
        _predict(_npy(t / "x.npy", v[:120]), d),
        "distinct points left on the structure after cleaning, the model needs at least 128"),
    "a cloud of a bare wall, no hook": lambda t, d, v, p: (
        _predict(_npy(t / "wall.npy", _bare_wall()), d), "wall.npy: no structure stands off the wall"),
    "--camera, a cloud with no plane": lambda t, d, v, p: (
        _predict(_npy(t / "ball.npy", _ball()), d, "--camera", "--level"),
        "ball.npy: no wall plane"),
    "--camera, a bare wall": lambda t, d, v, p: (
        _predict(_npy(t / "wall.npy", _camera_wall()), d, "--camera", "--level"),
        "wall.npy: no structure stands off the wall plane"),
    "--camera --up along the wall's normal": lambda t, d, v, p: (
        _predict(_npy(t / "wall.npy", _camera_wall()), d, "--camera", "--up", "0", "0", "-1"),
        "from the wall's normal"),
    "--camera, a cloud in millimetres": lambda t, d, v, p: (
        _predict(_npy(t / "wall.npy", 1000 * _camera_wall()), d, "--camera", "--level"),
        "wall.npy: median range 418 m from the camera — a cloud in millimetres?"),
    "--camera without --up or --level": lambda t, d, v, p: (
        _predict(_npy(t / "wall.npy", _camera_wall()), d, "--camera"),
        "--camera needs exactly one of --up X Y Z (camera frame) or --level"),
    "--camera --up of zeros": lambda t, d, v, p: (
        _predict(_npy(t / "wall.npy", _camera_wall()), d, "--camera", "--up", "0", "0", "0"),
        "--up: expected three finite numbers, not all zero"),
    "--camera --level, the wall sideways in the image": lambda t, d, v, p: (
        _predict(_npy(t / "wall.npy", _camera_wall()[:, [2, 0, 1]]), d, "--camera", "--level"),
        "--level: the wall faces sideways in the image"),
    "--up without --camera": lambda t, d, v, p: (
        _predict(_npy(t / "x.npy", v), d, "--up", "0", "0", "1"),
        "--up and --level go with --camera"),
    "--level without --camera": lambda t, d, v, p: (
        _predict(_npy(t / "x.npy", v), d, "--level"), "--up and --level go with --camera"),
    "--camera with --up and --level": lambda t, d, v, p: (
        _predict(_npy(t / "wall.npy", _camera_wall()), d, "--camera", "--level", "--up", "0", "-1",
                 "0"),
        "--camera needs exactly one of --up X Y Z (camera frame) or --level"),
    "--camera with --frame": lambda t, d, v, p: (
        _predict(_npy(t / "wall.npy", _camera_wall()), d, "--camera", "--level", "--frame",
                 _json(t / "f.json", np.eye(4).tolist())),
        "--camera finds the frame from the wall: drop --frame"),
    "frame not rigid": lambda t, d, v, p: (
        _predict(_npy(t / "x.npy", v), d, "--frame", _json(t / "f.json", (2 * np.eye(4)).tolist())),
        "f.json: not a rigid transform"),
    "frame not JSON": lambda t, d, v, p: (
        _predict(_npy(t / "x.npy", v), d, "--frame", _write(t / "f.json", b"{oops")),
        "f.json: not valid JSON"),
    "missing model folder": lambda t, d, v, p: (
        ["predict", _npy(t / "x.npy", v), "--model", t / "no_model", "-o", "OUT/skt.json"],
        "no_model: no such model folder"),
    "--samples with an SCTDN folder": lambda t, d, v, p: (
        _predict(_npy(t / "x.npy", v), d, "--samples", "3"),
        "--samples goes with an skt_flow model; "),
    "corrupt skt_flow checkpoint": lambda t, d, v, p: (
        ["predict", _npy(t / "x.npy", v), "--model",
         _corrupt(t, d / "train_baselines" / "skt_flow", "skt_flow"), "-o", "OUT/skt.json"],
        "cannot load the skt_flow checkpoint"),
    "corrupt checkpoint": lambda t, d, v, p: (
        ["predict", _npy(t / "x.npy", v), "--model", _corrupt(t, d / "train", "sctdn"), "-o",
         "OUT/skt.json"],
        "cannot load the SCTDN checkpoint"),
    "unknown --method": lambda t, d, v, p: (_hang(d, p, method="magic"), "invalid choice: 'magic'"),
    "--proposals 0": lambda t, d, v, p: (_hang(d, p, EASY_SUPPORT, OBJECT, "vatmart",
                                               "--proposals", "0"),
                                         "argument --proposals: expected a whole number from 1"),
    "--proposals with a method that does not propose": lambda t, d, v, p: (
        _hang(d, p, EASY_SUPPORT, OBJECT, "sctdn", "--proposals", "3"),
        "--proposals goes with a proposing method (vatmart, vatmart_mod, skt_flow), not "
        "--method sctdn"),
    "--model with a method that runs no model": lambda t, d, v, p: (
        _hang(d, p, EASY_SUPPORT, OBJECT, "kpam", "--model", d / "train"),
        "--model goes with a learned method"),
    "the method's trained model missing": lambda t, d, v, p: (
        _hang(_without(t, d, "train_baselines"), p, EASY_SUPPORT, OBJECT, "sctdn_cp_feature"),
        "train_baselines/sctdn_cp_feature: no such model folder: --method sctdn_cp_feature needs "
        "the trained sctdn_cp_feature model"),
    "--model missing, a mesh file to --keep": lambda t, d, v, p: (
        _hang(d, p, _box(t / "hook.stl", 0.05), OBJECT, "vatmart_mod", "--keep", "--model",
              t / "no_model"),
        "no_model: no such model folder: --method vatmart_mod needs"),
    "corrupt VAT-Mart checkpoint": lambda t, d, v, p: (
        _hang(d, p, EASY_SUPPORT, OBJECT, "vatmart", "--model",
              _corrupt(t, d / "train_baselines" / "vatmart", "vatmart")),
        "cannot load the VAT-Mart checkpoint"),
    "privileged method, support without a ground-truth SKT": lambda t, d, v, p: (
        _hang(d, p, _without_skt(d), OBJECT, "omnihang"),
        f"{_without_skt(d)}: has no ground-truth SKT in {d / 'rrt_skts' / 'skts.parquet'} (the "
        "planner failed on it); --method omnihang is privileged"),
    "unknown support": lambda t, d, v, p: (_hang(d, p, support="support_99999"),
                                           "support_99999: no such support"),
    "unknown object": lambda t, d, v, p: (_hang(d, p, obj="object_teapot_000"),
                                          "object_teapot_000: no such object"),
    "support without a ground-truth SKT": lambda t, d, v, p: (
        _hang(d, p, support=_without_skt(d)), f"{_without_skt(d)}: has no ground-truth"),
    "params typo": lambda t, d, v, p: (
        _hang(d, _write(t / "bad.yaml", p.read_text().replace("seed:", "sede:").encode())),
        "bad.yaml: common.sede: unknown key"),
    "params file missing": lambda t, d, v, p: (_hang(d, t / "none.yaml"), "none.yaml: params file not found"),
    "import: not a mesh": lambda t, d, v, p: (_import(_write(t / "x.obj", b"hello\n"), d, p),
                                              "x.obj: no triangles"),
    "import: unknown mesh format": lambda t, d, v, p: (_import(_write(t / "x.doc", b"hi\n"), d, p),
                                                       "x.doc: not a mesh trimesh can read"),
    "import: mesh in millimetres": lambda t, d, v, p: (_import(_box(t / "b.stl", 100.0), d, p),
                                                       "b.stl: 173.2 m across — a mesh in millimetres"),
    "import: hole beyond repair": lambda t, d, v, p: (_import(_open_sphere(t / "s.stl"), d, p),
                                                      "s.stl: not watertight — a hole of"),
    "import: no aperture": lambda t, d, v, p: (_import(_box(t / "b.obj", 0.1), d, p),
                                               "b.obj: no through-hole that a rod can pass"),
    "import: bad --name": lambda t, d, v, p: (_import(_box(t / "b.obj", 0.1), d, p, "a/b"),
                                              "--name: 'a/b' must be"),
}


#: Rows that argparse refuses (it exits instead of returning).
ARGPARSE = {"unknown --method", "--proposals 0"}


def _without(t, d, stage):
    """A data root in ``t`` with ``d``'s stage folders but ``stage``'s."""
    root = t / "root"
    root.mkdir()
    for entry in d.iterdir():
        if entry.name not in (stage, "user"):
            (root / entry.name).symlink_to(entry, target_is_directory=True)
    return root


def _without_skt(d) -> str:
    """The first support of the tiny data root that ``rrt_skts`` gave no SKT (which one depends
    on the planner; the tiny budget leaves several)."""
    import pandas as pd

    supports = pd.read_parquet(d / "mesh_gen" / "supports.parquet")["support_id"]
    planned = set(pd.read_parquet(d / "rrt_skts" / "skts.parquet")["support_id"])
    missing = sorted(set(supports) - planned)
    assert missing, "the tiny data root has an SKT on every support: this row needs one without"
    return missing[0]


def _import(mesh, d, params, name=None):
    return ["import-object", mesh, "--params", params, "--data-root", d,
            *(["--name", name] if name else [])]


def _box(path, size):
    import trimesh

    trimesh.creation.box([size] * 3).export(path)
    return path


def _open_sphere(path):
    import trimesh

    s = trimesh.creation.icosphere(5, radius=0.05)
    s.update_faces(s.triangles_center[:, 2] < 0.0)  # a hemisphere: a hole of ~130 edges
    s.export(path)
    return path


def _npy(path, a):
    np.save(path, a)
    return path


def _npz(path, **arrays):
    np.savez(path, **arrays)
    return path


def _json(path, obj):
    path.write_text(json.dumps(obj))
    return path


@pytest.mark.parametrize("row", list(ROWS))
def test_bad_input(row, capsys, tmp_path, data_root, view, tiny_dataset):
    params = tiny_dataset[0]
    (tmp_path / "OUT").mkdir()
    args, expected = ROWS[row](tmp_path, data_root, view, params)
    args = [str(a).replace("OUT", str(tmp_path / "OUT")) for a in args]
    before = tree_state(data_root)
    rc, out, err = run_skt(capsys, *args) if row not in ARGPARSE else _argparse(capsys, args)
    assert rc == 2, (row, err)
    lines = err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("ERROR:"), err
    assert expected in lines[0], lines[0]
    assert "Traceback" not in err + out
    assert list((tmp_path / "OUT").iterdir()) == []
    assert tree_state(data_root) == before


def _argparse(capsys, args):
    with pytest.raises(SystemExit) as e:
        run_skt(capsys, *args)
    _, err = capsys.readouterr()
    return e.value.code, "", err


def test_console_script_exits_2_without_traceback(tmp_path, data_root, view):
    """The installed ``skt`` script itself (a separate process); ``--debug`` adds the traceback."""
    np.save(tmp_path / "x.npy", view[:, :2])
    skt = shutil.which("skt", path=str(__import__("pathlib").Path(sys.executable).parent))
    args = [skt, "predict", str(tmp_path / "x.npy"), "--model", str(data_root / "train")]
    r = subprocess.run(args, capture_output=True, text=True)
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert r.stderr.strip().splitlines()[-1].startswith("ERROR: ") and "x.npy" in r.stderr
    r = subprocess.run([skt, "--debug", *args[1:]], capture_output=True, text=True)
    assert r.returncode == 2 and "Traceback" in r.stderr
