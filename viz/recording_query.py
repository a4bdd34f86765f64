"""What a viewer shows at each time of a recording's timeline, read from the ``.rrd``.

Latest-at semantics with clears, as the Rerun viewer applies them: an entity shows at time
``t`` of a timeline when it has data at or before ``t`` on that timeline (or static data) and
no clear of it, or recursive clear of an ancestor, came after that data and at or before
``t``. Used to check that per-item recordings show one item at a time.
"""

from collections import defaultdict
from pathlib import Path

import pyarrow as pa
from rerun.chunk import RrdReader

_ROW_ID = "rerun.controls.RowId"
_CLEAR = "Clear:is_recursive"


def _events(path: Path, timeline: str):
    """Per entity: static?, [(time, row id)] of data and [(time, row id, recursive)] of clears."""
    reader = RrdReader(path)
    (store,) = reader.recordings()
    static, data, clears = set(), defaultdict(list), defaultdict(list)
    for chunk in reader.stream(store=store).to_chunks():
        rb: pa.RecordBatch = chunk.to_record_batch()
        entity = chunk.entity_path
        components = [n for n in rb.schema.names if ":" in n and n != _CLEAR]
        is_static = not chunk.timeline_names
        if not is_static and timeline not in chunk.timeline_names:
            continue
        times = [None] * rb.num_rows if is_static else rb.column(timeline).to_pylist()
        ids = [bytes(x) for x in rb.column(_ROW_ID).to_pylist()]
        clear = rb.column(_CLEAR).to_pylist() if _CLEAR in rb.schema.names else [None] * rb.num_rows
        has_data = [any(v is not None for v in vals)
                    for vals in zip(*(rb.column(c).to_pylist() for c in components))] \
            if components else [False] * rb.num_rows
        for t, rid, c, d in zip(times, ids, clear, has_data):
            if d and is_static:
                static.add(entity)
            elif d and t is not None:
                data[entity].append((t, rid))
            if c is not None and t is not None:
                clears[entity].append((t, rid, bool(c[0] if isinstance(c, list) else c)))
    return static, data, clears


def _ancestors(entity: str) -> list[str]:
    parts = entity.strip("/").split("/")
    return ["/" + "/".join(parts[:i]) for i in range(1, len(parts) + 1)]


def visible_entities(path: str | Path, timeline: str) -> dict[int, set[str]]:
    """For every time value with data or clears on ``timeline``: the entities with temporal
    data shown there (static-only entities are left out: they show at every time)."""
    static, data, clears = _events(Path(path), timeline)
    times = sorted({t for ev in data.values() for t, _ in ev}
                   | {t for ev in clears.values() for t, _, _ in ev})
    out: dict[int, set[str]] = {}
    for t in times:
        shown = set()
        for entity, events in data.items():
            past = [e for e in events if e[0] <= t]
            if not past:
                continue
            last = max(past)
            cleared = any(
                last < (tc, rid) and tc <= t and (recursive or anc == entity)
                for anc in _ancestors(entity) for tc, rid, recursive in clears.get(anc, ()))
            if not cleared:
                shown.add(entity)
        out[t] = shown
    return out


def item_labels(path: str | Path, timeline: str, entity: str = "/item/info") -> dict[int, str]:
    """The text of ``entity`` (the item label) at each time of ``timeline`` where one was
    logged."""
    reader = RrdReader(Path(path))
    (store,) = reader.recordings()
    out = {}
    for chunk in reader.stream(store=store).to_chunks():
        if chunk.entity_path != entity or timeline not in chunk.timeline_names:
            continue
        rb = chunk.to_record_batch()
        for t, text in zip(rb.column(timeline).to_pylist(),
                           rb.column("TextDocument:text").to_pylist()):
            if t is not None and text is not None:
                out[t] = text[0] if isinstance(text, list) else text
    return out
