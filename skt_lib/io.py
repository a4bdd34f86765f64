"""On-disk formats: atomic writes, versioned Parquet schemas, checked reads.

Every artifact is written to a temporary file in the destination directory and renamed
into place, so a killed run never leaves a half-written file that looks valid.
"""

import io
import json
import os
import tempfile
import zipfile
from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq

from skt_lib.errors import DataError

_UMASK = os.umask(0)
os.umask(_UMASK)

SCHEMA_KEY = b"skt_hang.schema"
VERSION_KEY = b"skt_hang.schema_version"


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path next to ``path``; rename it onto ``path`` on success only."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        os.chmod(tmp_path, 0o666 & ~_UMASK)  # mkstemp makes 0600; give the usual mode
        os.replace(tmp_path, path)
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


def remove_partial_writes(directory: str | Path) -> int:
    """Delete the temporary files of :func:`atomic_path` left under ``directory`` by a writer
    that was killed (e.g. a Dask worker, whose task then ran again elsewhere); returns how
    many. Call it once the items writing there have finished."""
    stale = [p for p in Path(directory).rglob(".*.tmp") if p.is_file()]
    for p in stale:
        p.unlink()
    return len(stale)


def write_bytes_atomic(path: str | Path, data: bytes) -> None:
    with atomic_path(path) as tmp:
        tmp.write_bytes(data)


def write_text_atomic(path: str | Path, text: str) -> None:
    write_bytes_atomic(path, text.encode("utf-8"))


def write_json_atomic(path: str | Path, obj: object) -> None:
    """Deterministic JSON: sorted keys, 2-space indent, trailing newline."""
    write_text_atomic(path, json.dumps(obj, indent=2, sort_keys=True, allow_nan=False) + "\n")


@dataclass(frozen=True)
class TableSchema:
    """A named, versioned Parquet schema. ``columns`` maps name -> Arrow type."""

    name: str
    version: int
    columns: Mapping[str, pa.DataType]

    @property
    def arrow(self) -> pa.Schema:
        meta = {SCHEMA_KEY: self.name.encode(), VERSION_KEY: str(self.version).encode()}
        return pa.schema([pa.field(k, t, nullable=False) for k, t in self.columns.items()], meta)


def write_table(path: str | Path, rows: list[Mapping[str, object]], schema: TableSchema) -> None:
    """Write ``rows`` (dicts with exactly the schema's columns) as Parquet, atomically."""
    expected = set(schema.columns)
    for i, row in enumerate(rows):
        if set(row) != expected:
            missing, extra = expected - set(row), set(row) - expected
            raise DataError(
                f"{schema.name} row {i}: missing columns {sorted(missing)}, "
                f"unexpected columns {sorted(extra)}"
            )
    arrays = {k: [row[k] for row in rows] for k in schema.columns}
    try:
        table = pa.Table.from_pydict(arrays, schema=schema.arrow)
    except (pa.ArrowInvalid, pa.ArrowTypeError) as err:
        raise DataError(f"{schema.name}: values do not fit the schema: {err}") from None
    with atomic_path(path) as tmp:
        pq.write_table(table, tmp, compression="zstd")


def read_table(path: str | Path, schema: TableSchema):
    """Read a Parquet file written with ``schema``; check name, version, columns and types.

    Returns a :class:`pandas.DataFrame`.
    """
    path = Path(path)
    if not path.is_file():
        raise DataError(f"{path}: missing (expected {schema.name} table)")
    try:
        table = pq.read_table(path)
    except (pa.ArrowException, OSError) as err:
        raise DataError(f"{path}: not a readable Parquet file: {err}") from None
    meta = table.schema.metadata or {}
    name = meta.get(SCHEMA_KEY, b"?").decode()
    version = meta.get(VERSION_KEY, b"?").decode()
    if name != schema.name or version != str(schema.version):
        raise DataError(
            f"{path}: schema {name!r} v{version}, expected {schema.name!r} v{schema.version}"
        )
    for col, typ in schema.columns.items():
        if col not in table.column_names:
            raise DataError(f"{path}: missing column {col!r}")
        if not table.schema.field(col).type.equals(typ):
            raise DataError(
                f"{path}: column {col!r} has type {table.schema.field(col).type}, expected {typ}"
            )
    extra = set(table.column_names) - set(schema.columns)
    if extra:
        raise DataError(f"{path}: unexpected columns {sorted(extra)}")
    return table.to_pandas()


def write_npz_atomic(path: str | Path, arrays: Mapping[str, np.ndarray]) -> None:
    """An ``.npz`` (zip of ``.npy``, no pickle) with fixed entry dates, so equal arrays give
    equal bytes (numpy's own writer stamps the current time)."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", compression=zipfile.ZIP_DEFLATED) as zf:
        for name in sorted(arrays):
            arr = np.asarray(arrays[name])
            if arr.dtype == object:
                raise DataError(f"{path}: array {name!r} has dtype object (no pickles on disk)")
            data = io.BytesIO()
            np.lib.format.write_array(data, arr, allow_pickle=False)
            info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            zf.writestr(info, data.getvalue())
    write_bytes_atomic(path, buf.getvalue())


def read_npz(path: str | Path, spec: Mapping[str, tuple[str, int]]) -> dict[str, np.ndarray]:
    """Read an ``.npz`` and check it: ``spec`` maps key -> (dtype name, ndim)."""
    path = Path(path)
    if not path.is_file():
        raise DataError(f"{path}: missing")
    try:
        with np.load(path, allow_pickle=False) as z:
            out = {k: z[k] for k in z.files}
    except (OSError, ValueError, zipfile.BadZipFile, EOFError) as err:
        raise DataError(f"{path}: not a readable .npz: {err}") from None
    for key, (dtype, ndim) in spec.items():
        if key not in out:
            raise DataError(f"{path}: missing array {key!r}")
        a = out[key]
        if a.dtype.name != dtype or a.ndim != ndim:
            raise DataError(f"{path}: {key!r} is {a.dtype.name} with {a.ndim} dims, "
                            f"expected {dtype} with {ndim}")
        if a.dtype.kind == "f" and not np.isfinite(a).all():
            raise DataError(f"{path}: {key!r} has NaN or infinite values")
    return out
