"""Byte-reproducible Rerun recordings.

A recording written by the Rerun SDK differs in bytes on every run even when the logged data
is the same: row and chunk ids are time-based UIDs (wall clock + random counter), the SDK adds
a wall-clock ``log_time`` timeline, blueprint store ids are random, chunks leave the batcher
in hash-map order, and the ``.rrd`` footer (an optional index) is built from hash maps. A
recording inside a DVC output then changes the stage's hash on every run, and a fresh
clone's ``dvc repro`` can never match the committed ``dvc.lock``.

:func:`stabilise` rewrites a finished recording so that its bytes depend only on what was
logged and in which order:

- row ids become ``(base, rank)`` where ``rank`` is the row's position in the original
  (monotonic) id order, so "later log wins" is kept exactly;
- chunk ids are derived from the chunk's first row, and chunks are written in that order;
- wall-clock timelines (``log_time``, ``log_tick``) are dropped;
- each store (the recording, then its blueprint) is re-encoded by the SDK's own writer,
  its ``SetStoreInfo`` row id set to a constant, the blueprint store id and activation
  command written from fixed values, and the stream closed without the optional footer.

The data, its timelines and the blueprint are unchanged; ``rerun rrd verify`` accepts the
result and the viewer opens it as before. Tested for byte equality across processes in
``tests/test_viz.py``.
"""

import struct
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import pyarrow as pa
import xxhash
from rerun.chunk import Chunk, LazyChunkStream, RrdReader

from skt_lib.errors import DataError

ROW_ID_COLUMN = "rerun.controls.RowId"
WALL_CLOCK_TIMELINES = ("log_time", "log_tick")
_HEADER_BYTES = 12  # b"RRF2" + crate version + encoding options
_TRAILER_BYTES = 32  # footer offset u64, size u64, xxh32 u32, b"RRF2FOOT", version u32
_FOOTER_CRC_SEED = 7850921
_MSG_END, _MSG_STORE_INFO, _MSG_ARROW, _MSG_ACTIVATE = 0, 1, 2, 3
_KIND_RECORDING, _KIND_BLUEPRINT = 1, 2
# The time half of the synthetic ids, one per store: constant, so the bytes are too.
_BASE = {"recording": 1 << 60, "blueprint": 1 << 59}


def stabilise(raw: str | Path, out: str | Path, application_id: str, recording_id: str) -> None:
    """Rewrite the recording ``raw`` (one recording store, at most one blueprint) into ``out``
    with deterministic bytes. ``out`` is written directly: callers rename it into place."""
    reader = RrdReader(raw)
    recordings, blueprints = reader.recordings(), reader.blueprints()
    if len(recordings) != 1 or len(blueprints) > 1:
        raise DataError(f"{raw}: expected one recording and at most one blueprint, found "
                        f"{len(recordings)} and {len(blueprints)}")
    header, body = _encode_store(reader, recordings[0], "recording", application_id,
                                 recording_id)
    if blueprints:
        _, bp_body = _encode_store(reader, blueprints[0], "blueprint", application_id,
                                   f"{recording_id}-blueprint")
        body += bp_body
    stream = header + body + _message(_MSG_END, b"")
    Path(out).write_bytes(_with_stable_footer(stream))


def _with_stable_footer(stream: bytes) -> bytes:
    """Let Rerun's own ``rrd merge`` add the footer (chunk index) to a footer-less stream, then
    put the footer's hash-ordered parts (manifest order, schema field order) in sorted order
    and recompute its checksum."""
    with tempfile.TemporaryDirectory() as tmp:
        src, dst = Path(tmp) / "in.rrd", Path(tmp) / "out.rrd"
        src.write_bytes(stream)
        done = subprocess.run([sys.executable, "-m", "rerun", "rrd", "merge", str(src), "-o",
                               str(dst)], capture_output=True, text=True)
        if done.returncode != 0:
            raise DataError(f"rerun rrd merge failed: {done.stderr.strip()[-500:]}")
        merged = dst.read_bytes()
    messages = list(_messages(merged))
    if sorted(k for k, _ in messages) != sorted(k for k, _ in _messages(stream)) \
            or messages[-1][0] != _MSG_END:
        raise DataError("rerun rrd merge changed the message sequence")
    body_start = len(merged) - len(messages[-1][1]) - _TRAILER_BYTES  # of the End message
    trailer = merged[body_start + len(messages[-1][1]):]
    if len(trailer) != _TRAILER_BYTES or trailer[20:28] != b"RRF2FOOT":
        raise DataError("unexpected .rrd footer layout from rerun rrd merge")
    manifests = [_stable_manifest(v) for num, v in _pb_fields(messages[-1][1]) if num == 1]
    footer = b"".join(_field(1, m) for m in sorted(manifests))
    out = merged[:body_start - 16] + _message(_MSG_END, footer)
    crc = xxhash.xxh32(footer, seed=_FOOTER_CRC_SEED).intdigest()
    return out + struct.pack("<QQI", len(out) - len(footer), len(footer), crc) + trailer[20:]


def _stable_manifest(manifest: bytes) -> bytes:
    """``RrdManifest``: field 2 is ``Schema {arrow_schema = 1}``, its fields in hash order."""
    out = b""
    for num, value in _pb_fields(manifest):
        if num == 2:
            (schema_num, ipc), = _pb_fields(value)
            schema = pa.ipc.read_schema(pa.py_buffer(ipc))
            fields = sorted((_sorted_meta(f) for f in schema), key=lambda f: f.name)
            meta = dict(sorted((schema.metadata or {}).items()))
            ipc = pa.schema(fields, metadata=meta or None).serialize().to_pybytes()
            value = _field(schema_num, ipc)
        out += _field(num, value)
    return out


def _sorted_meta(field: pa.Field) -> pa.Field:
    return field.with_metadata(dict(sorted((field.metadata or {}).items())))


def _pb_fields(body: bytes) -> list[tuple[int, bytes]]:
    """Top-level fields of a protobuf message that has only length-delimited fields."""
    out, i = [], 0
    while i < len(body):
        key, i = _read_varint(body, i)
        if key & 7 != 2:
            raise DataError(f"unexpected protobuf wire type {key & 7} in .rrd footer")
        n, i = _read_varint(body, i)
        out.append((key >> 3, body[i:i + n]))
        i += n
    return out


def _read_varint(body: bytes, i: int) -> tuple[int, int]:
    n = shift = 0
    while True:
        byte = body[i]
        i += 1
        n |= (byte & 0x7F) << shift
        shift += 7
        if not byte & 0x80:
            return n, i


def _encode_store(reader: RrdReader, store, kind: str, application_id: str,
                  store_id: str) -> tuple[bytes, bytes]:
    chunks = _stable_chunks(reader.stream(store=store).to_chunks(), _BASE[kind])
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "store.rrd"
        LazyChunkStream.from_iter(chunks).write_rrd(
            path, application_id=application_id, recording_id=store_id)
        data = path.read_bytes()
    header, messages = data[:_HEADER_BYTES], list(_messages(data))
    infos = [b for k, b in messages if k == _MSG_STORE_INFO]
    arrows = [b for k, b in messages if k == _MSG_ARROW]
    if len(infos) != 1 or len(arrows) != len(chunks):
        raise DataError(f"unexpected .rrd layout from the Rerun writer: {len(infos)} store "
                        f"infos, {len(arrows)} chunks for {len(chunks)}")
    store_bytes = _store_id(application_id, store_id, _KIND_RECORDING)
    if kind == "blueprint":
        wanted = _store_id(application_id, store_id, _KIND_BLUEPRINT)
        infos = [_replace_once(b, store_bytes, wanted) for b in infos]
        arrows = [_replace_once(b, store_bytes, wanted) for b in arrows]
        store_bytes = wanted
    out = _message(_MSG_STORE_INFO, _fixed_row_id(infos[0], _BASE[kind]))
    out += b"".join(_message(_MSG_ARROW, b) for b in arrows)
    if kind == "blueprint":  # make it the active and default blueprint, as send_blueprint does
        command = _field(1, store_bytes) + b"\x10\x01\x18\x01"
        out += _message(_MSG_ACTIVATE, command)
    return header, out


def _stable_chunks(chunks: list[Chunk], base: int) -> list[Chunk]:
    """Chunks with wall-clock timelines dropped and ids replaced by order-preserving ones."""
    batches = []
    for chunk in chunks:
        rb = chunk.to_record_batch()
        keep = [i for i, name in enumerate(rb.schema.names) if name not in WALL_CLOCK_TIMELINES]
        batches.append(rb.select(keep))
    ids = [_row_ids(rb) for rb in batches]
    all_ids = np.concatenate(ids) if ids else np.zeros((0, 16), np.uint8)
    # Big-endian (time, counter) pairs: lexicographic byte order is the id order.
    order = np.lexsort(all_ids.T[::-1])
    if len(order) > 1 and (all_ids[order[1:]] == all_ids[order[:-1]]).all(axis=1).any():
        raise DataError("recording has duplicate row ids")
    rank = np.empty(len(order), np.int64)
    rank[order] = np.arange(1, len(order) + 1)
    out, start = [], 0
    for rb, n in zip(batches, (len(i) for i in ids)):
        ranks = rank[start:start + n]
        start += n
        new_ids = pa.array([_tuid(base, int(r)) for r in ranks], pa.binary(16))
        cols = [new_ids if name == ROW_ID_COLUMN else col
                for name, col in zip(rb.schema.names, rb.columns)]
        meta = dict(rb.schema.metadata or {})
        meta[b"rerun:id"] = ("chunk_%016X%016x" % (base + 1, int(ranks.min()))).encode()
        fields = [rb.schema.field(i) for i in range(rb.num_columns)]
        schema = pa.schema(fields, metadata=meta)
        (stable,) = Chunk.from_record_batch(pa.RecordBatch.from_arrays(cols, schema=schema))
        out.append((int(ranks.min()), stable))
    return [c for _, c in sorted(out, key=lambda t: t[0])]


def _row_ids(rb: pa.RecordBatch) -> np.ndarray:
    """The row-id column as an (n, 16) uint8 array (fixed-size binary, no copy)."""
    col = rb.column(ROW_ID_COLUMN)
    data = np.frombuffer(col.buffers()[1], np.uint8)
    return data[16 * col.offset: 16 * (col.offset + len(col))].reshape(-1, 16)


def _tuid(time_part: int, counter: int) -> bytes:
    return struct.pack(">QQ", time_part, counter)


def _messages(data: bytes):
    if data[:4] != b"RRF2":
        raise DataError("not a Rerun .rrd stream (no RRF2 header)")
    pos = _HEADER_BYTES
    while pos < len(data):
        kind, n = struct.unpack_from("<QQ", data, pos)
        yield kind, data[pos + 16: pos + 16 + n]
        pos += 16 + n
        if kind == _MSG_END:
            return


def _message(kind: int, body: bytes) -> bytes:
    return struct.pack("<QQ", kind, len(body)) + body


def _varint(n: int) -> bytes:
    out = bytearray()
    while True:
        byte, n = n & 0x7F, n >> 7
        out.append(byte | (0x80 if n else 0))
        if not n:
            return bytes(out)


def _field(number: int, payload: bytes) -> bytes:
    """A length-delimited protobuf field."""
    return _varint(number << 3 | 2) + _varint(len(payload)) + payload


def _store_id(application_id: str, store_id: str, kind: int) -> bytes:
    """Protobuf ``StoreId {kind = 1; recording_id = 2; application_id = 3 {id = 1}}``."""
    return (b"\x08" + _varint(kind) + _field(2, store_id.encode())
            + _field(3, _field(1, application_id.encode())))


def _replace_once(body: bytes, old: bytes, new: bytes) -> bytes:
    if body.count(old) != 1:
        raise DataError("unexpected .rrd message layout: store id not found exactly once")
    return body.replace(old, new)


def _fixed_row_id(store_info: bytes, base: int) -> bytes:
    """``SetStoreInfo`` starts with ``row_id = 1: Tuid {fixed64 time = 1; fixed64 inc = 2}``."""
    if store_info[:3] != b"\x0a\x12\x09" or store_info[11:12] != b"\x11":
        raise DataError("unexpected SetStoreInfo layout in the Rerun writer's output")
    return (store_info[:3] + struct.pack("<Q", base) + b"\x11" + struct.pack("<Q", 0)
            + store_info[20:])
