"""Are the geometry bytes the same in this environment? Builds every ``mesh_gen`` item with
the pipeline's own builders (no report, no recording) and compares each file it writes,
byte for byte, with ``data/mesh_gen`` (the committed run's output).

    .venv/bin/python -m tools.geometry_bytes                       # build here and compare
    .venv/bin/python -m tools.geometry_bytes --json out.json       # also write every md5
    .venv/bin/python -m tools.geometry_bytes --against other.json  # compare two environments

Run it on a second machine (or under ``OPENBLAS_CORETYPE`` / ``NPY_DISABLE_CPU_FEATURES``)
with the same ``requirements.lock`` versions; exit 1 when any file differs or is missing.
"""

import argparse
import hashlib
import json
import os
import platform
import sys
import tempfile
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

from skt_lib.config import OBJECT_CATEGORIES
from skt_lib.config.params_file import load_params
from skt_lib.geometry.build import ObjectTask, SupportTask, build_object, build_support

ROOT = Path(__file__).resolve().parents[1]


def _build(task) -> dict:
    return (build_support if isinstance(task, SupportTask) else build_object)(task)


def file_md5s(folder: Path) -> dict[str, str]:
    """md5 of every file under ``folder``'s ``supports/`` and ``objects/``, by relative path."""
    return {str(f.relative_to(folder)): hashlib.md5(f.read_bytes()).hexdigest()
            for sub in ("supports", "objects") for f in sorted((folder / sub).rglob("*"))
            if f.is_file()}


def build_all(params_path: Path, out: Path, workers: int) -> dict[str, str]:
    """Every support and object of ``params_path``'s ``mesh_gen`` built under ``out``."""
    params = load_params(params_path)
    p, seed = params.mesh_gen, params.common.seed
    tasks = [SupportTask(seed, i, p, str(out)) for i in range(p.n_supports)]
    tasks += [ObjectTask(seed, "reference", 0, p, str(out))]
    tasks += [ObjectTask(seed, c, k, p, str(out)) for c in OBJECT_CATEGORIES
              for k in range(p.n_objects_per_category)]
    with ProcessPoolExecutor(workers) as ex:
        list(ex.map(_build, tasks))
    return file_md5s(out)


def compare(ours: dict[str, str], theirs: dict[str, str]) -> list[str]:
    """Paths that differ or are missing on one side."""
    return sorted(k for k in set(ours) | set(theirs) if ours.get(k) != theirs.get(k))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--params", type=Path, default=ROOT / "params.yaml")
    ap.add_argument("--against", type=Path, help="md5 JSON of another environment "
                    "(default: the files of data/mesh_gen)")
    ap.add_argument("--json", type=Path, help="write this environment's md5s here")
    ap.add_argument("--workers", type=int, default=os.cpu_count())
    args = ap.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        ours = build_all(args.params, Path(tmp), args.workers)
    env = {"machine": platform.processor() or platform.machine(), "python": sys.version.split()[0],
           "OPENBLAS_CORETYPE": os.environ.get("OPENBLAS_CORETYPE", ""),
           "NPY_DISABLE_CPU_FEATURES": os.environ.get("NPY_DISABLE_CPU_FEATURES", "")}
    if args.json:
        args.json.write_text(json.dumps({"env": env, "md5": ours}, indent=1) + "\n")
    theirs = (json.loads(args.against.read_text())["md5"] if args.against
              else file_md5s(ROOT / "data" / "mesh_gen"))
    differ = compare(ours, theirs)
    print(f"{len(ours)} files built ({env}); {len(ours) - len(differ)} equal, "
          f"{len(differ)} differ or missing" + "".join(f"\n  {k}" for k in differ[:20]))
    return 1 if differ or not ours else 0


if __name__ == "__main__":
    sys.exit(main())
