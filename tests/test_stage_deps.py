"""Every project module a stage runs is one of its DVC deps (tools/stage_deps.py): else a
change there would leave the stage's results stale and ``dvc status`` silent."""

from pathlib import Path

import yaml

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


def _downstream(stages: dict) -> dict[str, set[str]]:
    """Stage → the stages after it (those that read what it writes, and so on)."""
    outs = {name: [ROOT / (o if isinstance(o, str) else next(iter(o))) for o in s.get("outs", [])]
            for name, s in stages.items()}
    reads = {name: {other for other, paths in outs.items() if other != name and any(
        (ROOT / d) == o or o in (ROOT / d).parents or (ROOT / d) in o.parents
        for d in s.get("deps", []) for o in paths)} for name, s in stages.items()}
    after = {name: set() for name in stages}
    changed = True
    while changed:
        changed = False
        for name in stages:
            for up in list(reads[name]):
                new = ({name} | after[name]) - after[up]
                if new:
                    after[up] |= new
                    changed = True
    return after


def test_a_section_of_the_config_reruns_only_its_stage_and_the_stages_after_it():
    """Each stage's parameters are its own module (skt_lib/config/<stage>.py): only that stage,
    its downstream and a stage that reads the whole section as its own params (train_baselines
    trains with train's) depend on it, so editing one help string reruns no other stage."""
    stages = yaml.safe_load((ROOT / "dvc.yaml").read_text())["stages"]
    after = _downstream(stages)
    assert after["mesh_gen"] == set(stages) - {"mesh_gen"}  # the DAG is read right
    assert after["sim_eval"] == set()
    for name in stages:
        module = f"skt_lib/config/{name}.py"
        assert (ROOT / module).is_file(), f"{name}: no section module {module}"
        readers = {s for s, st in stages.items() if module in st.get("deps", [])}
        whole = {s for s, st in stages.items() if name in st.get("params", [])}
        assert name in readers, f"{name} does not depend on its own section {module}"
        assert readers <= {name} | after[name] | whole, \
            f"{module}: stages before {name} depend on it: {sorted(readers - after[name] - {name})}"
    # the fields an earlier stage reads from a later section are modules of their own
    for module, reader in (("waypoints", "rrt_skts"), ("physics", "contact_sim"),
                           ("proposals", "train_baselines")):
        readers = {s for s, st in stages.items() if f"skt_lib/config/{module}.py" in st.get("deps", [])}
        assert reader in readers and readers <= {reader} | after[reader], (module, readers)
