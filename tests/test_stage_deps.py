"""Every project module a stage runs is one of its DVC deps (tools/stage_deps.py): else a
change there would leave the stage's results stale and ``dvc status`` silent."""

from pathlib import Path

from tools.stage_deps import ROOT, closure, missing


def test_every_stage_lists_every_module_it_runs():
    assert missing(ROOT) == {}


def _write(root: Path, rel: str, text: str) -> None:
    path = root / rel
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(text)


def test_a_module_imported_two_steps_away_is_missing_until_listed(tmp_path):
    _write(tmp_path, "stages/__init__.py", "")
    _write(tmp_path, "stages/train.py", "from skt_lib.learning.fit import fit\n")
    _write(tmp_path, "skt_lib/__init__.py", '"""The library."""\n__version__ = "0"\n')
    _write(tmp_path, "skt_lib/learning/__init__.py", "from skt_lib.io import read\n")
    _write(tmp_path, "skt_lib/learning/fit.py", "import numpy\nfrom skt_lib import seeding\n")
    _write(tmp_path, "skt_lib/seeding.py", "")
    _write(tmp_path, "skt_lib/io.py", "")
    stage = ("stages:\n  train:\n    cmd: python -m stages.train\n"
             "    deps:\n      - stages/train.py\n")
    _write(tmp_path, "dvc.yaml", stage + "      - skt_lib/learning\n")
    # the package's __init__ runs and imports io; seeding comes in through a from-import
    assert missing(tmp_path) == {"train": ["skt_lib/io.py", "skt_lib/seeding.py"]}
    # an __init__ with a docstring and __version__ only decides nothing
    assert tmp_path / "skt_lib/__init__.py" not in closure("stages.train", tmp_path)
    _write(tmp_path, "dvc.yaml", stage + "      - skt_lib\n")
    assert missing(tmp_path) == {}


def test_caches_beside_the_code_are_not_part_of_a_dep():
    """numba writes its cache (*.nbi, *.nbc) into __pycache__ beside the source; in a dep
    directory's hash it made dvc.lock differ on every machine (skt_lib/sim: 52 files here,
    22 on a fresh clone)."""
    import subprocess
    import sys

    dvc = Path(sys.executable).with_name("dvc")
    for path in ("skt_lib/sim/__pycache__/ik_kernel.solve-179.py311.nbi",
                 "skt_lib/learning/__pycache__/predictor.cpython-311.pyc"):
        out = subprocess.run([str(dvc), "check-ignore", path], cwd=ROOT, capture_output=True,
                             text=True)
        assert out.returncode == 0 and out.stdout.strip() == path, (path, out.stderr)
    assert subprocess.run([str(dvc), "check-ignore", "skt_lib/sim/ik_kernel.py"],
                          cwd=ROOT, capture_output=True).returncode == 1
