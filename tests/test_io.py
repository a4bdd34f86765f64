import pyarrow as pa
import pytest

from skt_lib.errors import DataError
from skt_lib.io import TableSchema, atomic_path, read_table, write_json_atomic, write_table

S = TableSchema("demo", 2, {"id": pa.string(), "x": pa.float64(), "v": pa.list_(pa.float64(), 3)})
ROWS = [{"id": "a", "x": 1.5, "v": [1.0, 2.0, 3.0]}, {"id": "b", "x": -2.0, "v": [0.0, 0.0, 1.0]}]


def test_roundtrip_is_exact_and_bytes_are_stable(tmp_path):
    write_table(tmp_path / "t.parquet", ROWS, S)
    df = read_table(tmp_path / "t.parquet", S)
    assert df["id"].tolist() == ["a", "b"]
    assert df["x"].tolist() == [1.5, -2.0]
    assert [list(v) for v in df["v"]] == [r["v"] for r in ROWS]
    write_table(tmp_path / "u.parquet", ROWS, S)
    assert (tmp_path / "t.parquet").read_bytes() == (tmp_path / "u.parquet").read_bytes()


def test_wrong_rows_are_rejected_before_writing(tmp_path):
    with pytest.raises(DataError, match="missing columns"):
        write_table(tmp_path / "t.parquet", [{"id": "a", "x": 1.0}], S)
    with pytest.raises(DataError, match="do not fit"):
        write_table(tmp_path / "t.parquet", [{"id": "a", "x": "no", "v": [1.0, 2.0, 3.0]}], S)
    assert list(tmp_path.iterdir()) == []


def test_schema_name_version_and_types_are_checked(tmp_path):
    write_table(tmp_path / "t.parquet", ROWS, S)
    with pytest.raises(DataError, match="expected 'demo' v3"):
        read_table(tmp_path / "t.parquet", TableSchema("demo", 3, S.columns))
    other = TableSchema("demo", 2, {"id": pa.string(), "x": pa.int64(), "v": S.columns["v"]})
    with pytest.raises(DataError, match="column 'x' has type double"):
        read_table(tmp_path / "t.parquet", other)


def test_corrupted_and_missing_files(tmp_path):
    path = tmp_path / "t.parquet"
    write_table(path, ROWS, S)
    path.write_bytes(path.read_bytes()[:40])
    with pytest.raises(DataError, match="not a readable Parquet"):
        read_table(path, S)
    with pytest.raises(DataError, match="missing"):
        read_table(tmp_path / "none.parquet", S)


def test_atomic_path_leaves_nothing_on_failure(tmp_path):
    target = tmp_path / "out.bin"
    with pytest.raises(RuntimeError):
        with atomic_path(target) as tmp:
            tmp.write_bytes(b"half")
            raise RuntimeError("killed")
    assert list(tmp_path.iterdir()) == []


def test_json_is_deterministic_and_rejects_nan(tmp_path):
    write_json_atomic(tmp_path / "a.json", {"b": 1, "a": [1, 2]})
    assert (tmp_path / "a.json").read_text() == '{\n  "a": [\n    1,\n    2\n  ],\n  "b": 1\n}\n'
    with pytest.raises(ValueError):
        write_json_atomic(tmp_path / "n.json", {"x": float("nan")})
    assert not (tmp_path / "n.json").exists()


def test_atomic_files_get_the_usual_mode(tmp_path):
    import os
    import stat

    write_json_atomic(tmp_path / "m.json", {"a": 1})
    umask = os.umask(0)
    os.umask(umask)
    assert stat.S_IMODE((tmp_path / "m.json").stat().st_mode) == 0o666 & ~umask


def test_remove_partial_writes_only_touches_atomic_temp_files(tmp_path):
    from skt_lib.io import remove_partial_writes

    (tmp_path / "sub").mkdir()
    keep = [tmp_path / "a.npz", tmp_path / "sub" / ".hidden", tmp_path / "sub" / "b.tmp"]
    gone = [tmp_path / ".a.npz.x1y2.tmp", tmp_path / "sub" / ".m.obj.zz.tmp"]
    for p in keep + gone:
        p.write_bytes(b"x")
    assert remove_partial_writes(tmp_path) == 2
    assert all(p.exists() for p in keep) and not any(p.exists() for p in gone)
    assert remove_partial_writes(tmp_path / "missing") == 0
