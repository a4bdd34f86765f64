"""The command line is the top layer of the library: no module of ``skt_lib`` outside
``skt_lib/cli/`` imports ``skt_lib.cli`` (what both need lives below both, e.g.
:mod:`skt_lib.items`), read from the source with ``ast`` so lazy imports count too."""

import ast
from pathlib import Path

import skt_lib

PACKAGE = Path(skt_lib.__file__).parent
CLI = "skt_lib.cli"


def _module(path: Path, package: Path) -> str:
    rel = path.relative_to(package.parent).with_suffix("")
    parts = rel.parts[:-1] if rel.name == "__init__" else rel.parts
    return ".".join(parts)


def cli_imports(path: Path, package_dir: Path = PACKAGE) -> list[str]:
    """``skt_lib.cli`` modules the file at ``path`` (in the package at ``package_dir``)
    imports, absolutely or relatively: ``file:line: module`` each."""
    name = _module(path, package_dir)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            targets = [a.name for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                anchor = package.split(".")[:len(package.split(".")) - node.level + 1]
                base = ".".join([*anchor, *([base] if base else [])])
            targets = [base, *(f"{base}.{a.name}" for a in node.names)]
        else:
            continue
        found += [f"{path.relative_to(package_dir.parent)}:{node.lineno}: {t}" for t in targets
                  if t == CLI or t.startswith(CLI + ".")]
    return found


def test_nothing_below_the_cli_imports_it():
    files = [p for p in sorted(PACKAGE.rglob("*.py")) if CLI.split(".")[1] not in
             p.relative_to(PACKAGE).parts[:1]]
    assert len(files) > 50  # the whole package, not an empty glob
    assert [hit for f in files for hit in cli_imports(f)] == []


def test_the_check_sees_each_way_of_importing(tmp_path):
    lines = {"import skt_lib.cli.hang": True, "from skt_lib.cli import items": True,
             "from skt_lib import cli": True, "from ..cli.common import progress": True,
             "from . import cli": True, "from skt_lib import items": False,
             "import skt_lib.client": False, "from ..clipping import x": False}
    pkg = tmp_path / "skt_lib"
    (pkg / "eval").mkdir(parents=True)
    for i, (line, hit) in enumerate(lines.items()):
        where = pkg / "eval" / f"m{i}.py" if line.startswith("from ..") else pkg / f"m{i}.py"
        where.write_text(f"def f():\n    {line}\n")
        assert bool(cli_imports(where, pkg)) == hit, line
