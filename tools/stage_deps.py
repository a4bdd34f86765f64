"""Which project modules each DVC stage runs that ``dvc.yaml`` does not list as its deps.

A stage's results are decided by every module of ours it imports, not only by its own
files: ``sim_eval`` predicts with ``skt_lib/learning``, so a change there must rerun it even
when the trained weights come out the same. The import closure is read statically (``ast``:
absolute imports of ``skt_lib``, ``viz`` and ``stages``, with their parent packages); an
``__init__.py`` that holds only a docstring and ``__version__`` decides nothing and is left out.

    python -m tools.stage_deps          # print what is missing, exit 1 if anything is
"""

import ast
import sys
from pathlib import Path

import yaml

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("skt_lib", "viz", "stages")


def _file(module: str, root: Path) -> Path | None:
    path = root.joinpath(*module.split("."))
    if path.with_suffix(".py").is_file():
        return path.with_suffix(".py")
    return path / "__init__.py" if (path / "__init__.py").is_file() else None


def _imports(path: Path) -> set[str]:
    found = set()
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if isinstance(node, ast.Import):
            found |= {a.name for a in node.names}
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            found |= {node.module, *(f"{node.module}.{a.name}" for a in node.names)}
    return {m for m in found if m.split(".")[0] in PACKAGES}


def _decides_nothing(path: Path) -> bool:
    """An ``__init__.py`` with nothing but a docstring and ``__version__``."""
    if path.name != "__init__.py":
        return False
    body = ast.parse(path.read_text()).body
    return all((isinstance(n, ast.Expr) and isinstance(n.value, ast.Constant))
               or (isinstance(n, ast.Assign) and [t.id for t in n.targets
                                                  if isinstance(t, ast.Name)] == ["__version__"])
               for n in body)


def closure(module: str, root: Path = ROOT) -> set[Path]:
    """Every project file importing ``module`` runs (parent packages included)."""
    seen, todo = set(), [module]
    while todo:
        name = todo.pop()
        path = _file(name, root)
        if path is None or path in seen:
            continue
        seen.add(path)
        parts = name.split(".")
        todo += [".".join(parts[:i]) for i in range(1, len(parts))]
        todo += sorted(_imports(path))
    return {p for p in seen if not _decides_nothing(p)}


def missing(root: Path = ROOT) -> dict[str, list[str]]:
    """Stage → project files it runs that are not (under) one of its ``dvc.yaml`` deps."""
    stages = yaml.safe_load((root / "dvc.yaml").read_text())["stages"]
    out = {}
    for name, stage in stages.items():
        deps = [root / d for d in stage.get("deps", [])]
        module = stage["cmd"].split("python -m ", 1)[1].split()[0]
        lacking = sorted(str(p.relative_to(root)) for p in closure(module, root)
                         if not any(p == d or d in p.parents for d in deps))
        if lacking:
            out[name] = lacking
    return out


def main() -> int:
    gaps = missing()
    for name, files in gaps.items():
        print(f"{name}: {' '.join(files)}")
    return 1 if gaps else 0


if __name__ == "__main__":
    sys.exit(main())
