"""The layer order of ``[tool.importlinter]`` in pyproject.toml holds: ``lint-imports`` (the
import-linter command) passes on the project, every top-level module of ``skt_lib`` has a
place in the order, and an upward or forbidden import in a copy of the project fails it.

import-linter reads every import statement, function-level (lazy) and relative ones too, and
follows chains: ``a -> b -> c`` breaks a contract that forbids ``a -> c``."""

import pkgutil
import shutil
import subprocess
import sys
import tomllib
from pathlib import Path

import pytest

import skt_lib

ROOT = Path(__file__).resolve().parents[1]
CONFIG = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]
LINT = "import sys; from importlinter.cli import lint_imports_command; sys.exit(lint_imports_command())"


def lint_imports(cwd: Path, *args: str) -> subprocess.CompletedProcess:
    """``lint-imports`` of this venv run in ``cwd`` (which it puts first on ``sys.path`` and
    reads ``pyproject.toml`` from), no cache written."""
    return subprocess.run([sys.executable, "-c", LINT, "--no-cache", *args], cwd=cwd,
                          capture_output=True, text=True, timeout=300)


def _layered() -> set[str]:
    (layers,) = [c["layers"] for c in CONFIG["contracts"] if c["type"] == "layers"]
    return {m.strip() for layer in layers for part in layer.split("|") for m in part.split(":")}


def test_the_import_contracts_hold():
    got = lint_imports(ROOT)
    n = len(CONFIG["contracts"])
    assert got.returncode == 0 and f"Contracts: {n} kept, 0 broken." in got.stdout, \
        got.stdout + got.stderr


def test_every_top_level_module_has_a_layer():
    """A new ``skt_lib/<name>.py`` or package is placed in the order, not left unchecked."""
    top = {f"skt_lib.{m.name}" for m in pkgutil.iter_modules(skt_lib.__path__)}
    assert len(top) > 15 and "skt_lib.cli" in top  # the whole package, not an empty listing
    assert top - _layered() == set()
    assert {"tools", "stages", "viz"} <= _layered() and set(CONFIG["root_packages"]) == {
        "skt_lib", "viz", "stages", "tools"}


#: (file, code appended to it, a line lint-imports must print): one way each of breaking a
#: contract — upward (absolute, relative and lazy), between independent siblings, and the
#: libraries the code below the command line must not import.
BREAKS = [
    ("skt_lib/geometry/se3.py", "import skt_lib.eval.methods",
     "skt_lib.geometry is not allowed to import skt_lib.eval"),
    ("skt_lib/eval/metrics.py", "def _lazy():\n    from ..cli.common import progress",
     "skt_lib.eval is not allowed to import skt_lib.cli"),
    ("skt_lib/learning/train.py", "from skt_lib.planning import skts",
     "skt_lib.learning is not allowed to import skt_lib.planning"),
    ("stages/bench.py", "from tools import docs_results",
     "stages is not allowed to import tools"),
    ("skt_lib/io.py", "from tqdm import tqdm", "skt_lib is not allowed to import tqdm"),
    ("skt_lib/learning/flow.py", "import matplotlib.pyplot as plt",
     "skt_lib is not allowed to import matplotlib"),
    ("viz/figures.py", "def _lazy():\n    import tqdm", "viz is not allowed to import tqdm"),
]


@pytest.mark.parametrize("path, code, message", BREAKS, ids=[b[0] for b in BREAKS])
def test_an_import_against_the_order_fails_it(tmp_path, path, code, message):
    """The project copied (its packages and pyproject.toml) and one import added: lint-imports
    exits non-zero and names the broken rule; the untouched copy passes."""
    for package in CONFIG["root_packages"]:
        shutil.copytree(ROOT / package, tmp_path / package,
                        ignore=shutil.ignore_patterns("__pycache__"))
    shutil.copy(ROOT / "pyproject.toml", tmp_path)
    assert lint_imports(tmp_path).returncode == 0
    target = tmp_path / path
    target.write_text(target.read_text() + f"\n\n{code}\n")
    got = lint_imports(tmp_path, "--config", str(tmp_path / "pyproject.toml"))
    assert got.returncode != 0 and message in got.stdout, got.stdout + got.stderr
