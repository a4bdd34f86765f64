"""Resumable per-item work: finished items survive a killed stage.

A stage's per-item results are written, one file per item, as they finish, under

    <data dir's parent>/.work/<stage>/<fingerprint>/<item key>.pkl

(``data/.work/rrt_skts/…`` in the repository: outside every DVC output, so ``dvc repro``,
which deletes a stage's outputs before running it, leaves them alone; git-ignored).

- The **fingerprint** hashes everything a stage's results depend on, as ``dvc.yaml`` declares
  it: the content of every dependency (code and upstream artifacts, ``data/…`` read from the
  run's ``--data-root``) and the values of the stage's params. Results made under other
  params, code or inputs sit under another fingerprint and are never reused; they are
  deleted when the stage starts.
- The **item key** hashes the task function's name and a canonical form of the task (its
  id, seed, params, arrays), so a changed item list reuses exactly the unchanged items.
- Each file is written to a temporary name and renamed, so a kill leaves either a complete
  result or nothing. A file that cannot be read back is recomputed.
- When the stage has written its artifacts it calls :meth:`ItemStore.finish`, which deletes
  the stage's work folder.

Results are pickled: this is the stage's own scratch space, written and read by the same
code (as the process pool and Dask already pickle them), never a data artifact.
"""

import dataclasses
import hashlib
import json
import logging
import pickle
import shutil
from pathlib import Path, PurePath
from types import SimpleNamespace

import numpy as np
import yaml

from skt_lib.errors import DataError
from skt_lib.io import write_bytes_atomic

log = logging.getLogger(__name__)
REPO = Path(__file__).resolve().parents[1]
WORK_DIR = ".work"
class ItemStore:
    """Finished per-item results of one stage run (see the module docstring)."""

    MISSING = object()  # what :meth:`load` returns for an item not finished yet

    def __init__(self, folder: Path):
        self.folder = Path(folder)

    @classmethod
    def for_stage(cls, stage: str, params_path: str | Path, data_root: str | Path,
                  data_dir: str | Path) -> "ItemStore":
        """The store for ``stage`` run with these arguments; stale fingerprints are removed."""
        base = Path(data_dir).resolve().parent / WORK_DIR / stage
        fingerprint = stage_fingerprint(stage, params_path, data_root)
        if base.is_dir():
            for old in base.iterdir():
                if old.name != fingerprint:
                    log.info("removing work of an earlier run under other inputs: %s", old)
                    shutil.rmtree(old, ignore_errors=True)
        return cls(base / fingerprint)

    @staticmethod
    def key(fn, item) -> str:
        """sha256 of the task function's name and a canonical form of the item (not its
        pickle: pickled sets, e.g. pydantic's fields-set, change order between processes)."""
        name = f"{getattr(fn, '__module__', '')}.{getattr(fn, '__qualname__', repr(fn))}"
        text = json.dumps([name, _canonical(item)], sort_keys=True, allow_nan=True)
        return hashlib.sha256(text.encode()).hexdigest()[:32]

    def load(self, key: str):
        """The stored result for ``key``, or :attr:`MISSING`."""
        path = self.folder / f"{key}.pkl"
        try:
            return pickle.loads(path.read_bytes())
        except FileNotFoundError:
            return self.MISSING
        except Exception as err:  # a damaged file: recompute the item
            log.warning("ignoring unreadable work file %s: %s", path, err)
            return self.MISSING

    def save(self, key: str, result) -> None:
        write_bytes_atomic(self.folder / f"{key}.pkl", pickle.dumps(result, protocol=5))

    def finish(self) -> None:
        """The stage's artifacts are written: delete its work folder."""
        shutil.rmtree(self.folder.parent, ignore_errors=True)
        try:
            self.folder.parent.parent.rmdir()  # .work itself, when it is empty
        except OSError:
            pass


_SCALARS = frozenset({type(None), bool, int, float, str})


def _canonical(obj):
    """A JSON-able form of a task that is equal exactly when the tasks are equal."""
    if obj is None or isinstance(obj, (bool, int, float, str)):
        return obj
    if isinstance(obj, (list, tuple)):
        if all(type(v) in _SCALARS for v in obj):  # e.g. a pose's floats: themselves, fast
            return list(obj)
        return [_canonical(v) for v in obj]
    if isinstance(obj, (set, frozenset)):
        return sorted((_canonical(v) for v in obj), key=repr)
    if isinstance(obj, dict):
        return {str(k): _canonical(v) for k, v in sorted(obj.items(), key=lambda kv: repr(kv[0]))}
    if isinstance(obj, np.ndarray):
        return {"ndarray": [str(obj.dtype), list(obj.shape),
                            hashlib.sha256(np.ascontiguousarray(obj).tobytes()).hexdigest()]}
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, PurePath):
        return str(obj)
    if dataclasses.is_dataclass(obj):
        return {type(obj).__qualname__: {f.name: _canonical(getattr(obj, f.name))
                                         for f in dataclasses.fields(obj)}}
    if isinstance(obj, SimpleNamespace):
        return {"SimpleNamespace": _canonical(vars(obj))}
    if hasattr(obj, "model_dump"):  # pydantic params sections
        return {type(obj).__qualname__: _canonical(obj.model_dump(mode="python"))}
    raise TypeError(f"cannot key a task containing {type(obj).__name__}; "
                    "add it to skt_lib.resume._canonical")


def stage_fingerprint(stage: str, params_path: str | Path, data_root: str | Path) -> str:
    """sha256 over the stage's declared deps (contents) and params (values) in dvc.yaml."""
    try:
        spec = yaml.safe_load((REPO / "dvc.yaml").read_text())["stages"][stage]
    except (OSError, KeyError, TypeError, yaml.YAMLError) as err:
        raise DataError(f"{REPO / 'dvc.yaml'}: no stage {stage!r} to fingerprint: {err}") from None
    h = hashlib.sha256(f"stage {stage}\n".encode())
    for dep in spec.get("deps", []):
        path = Path(data_root) / dep[len("data/"):] if dep.startswith("data/") else REPO / dep
        h.update(f"dep {dep}\n".encode())
        _hash_path(h, path)
    params = yaml.safe_load(Path(params_path).read_text()) or {}
    for name in spec.get("params", []):
        value = params
        for part in str(name).split("."):
            value = value.get(part) if isinstance(value, dict) else None
        h.update(f"param {name}={json.dumps(value, sort_keys=True)}\n".encode())
    return h.hexdigest()[:24]


def _hash_path(h, path: Path) -> None:
    if path.is_file():
        files = [path]
    elif path.is_dir():
        files = sorted(p for p in path.rglob("*") if p.is_file() and "__pycache__" not in p.parts)
    else:
        h.update(b"missing\n")
        return
    for f in files:
        h.update(f"{f.relative_to(path) if f != path else ''}\n".encode())
        with open(f, "rb") as fh:
            h.update(hashlib.file_digest(fh, "sha256").digest())
