"""One recording for a newcomer's first look: a few representative items of every stage's
recording side by side, one tab per stage (``make review`` writes ``data/review/review.rrd``).

Each stage's entities move under ``/<stage>/``. Per item timeline the first item of each
difficulty level (supports), category (objects) or method (trials) is kept, renumbered
0, 1, … on the same timeline, and shown one at a time as in the stage recording; the
``step`` timeline of ``sim_eval`` is left out (the ``trial`` timeline shows each trial's end
state). Tabs share the timelines: at ``support`` = 2, every support tab shows its third
representative.
"""

import re
import struct
from pathlib import Path

import numpy as np
import pyarrow as pa
import rerun as rr
import rerun.blueprint as rrb
from rerun.chunk import Chunk, RrdReader

from viz.recording_query import item_labels
from viz.rerun_log import (INFO, OBJECT_EYE, OBJECT_LOOK_AT, SKT_EYE, SKT_LOOK_AT, SUPPORT_EYE,
                           SUPPORT_LOOK_AT, recording)

_ROW_ID = "rerun.controls.RowId"
_CLEAR = "Clear:is_recursive"
# stage: (item timeline, label field choosing representatives, eye, look-at)
REVIEW = {
    "mesh_gen": ("support", "level", SUPPORT_EYE, SUPPORT_LOOK_AT),
    "contact_sim": ("support", "level", SUPPORT_EYE, SUPPORT_LOOK_AT),
    "rotation_extraction": ("object", "category", OBJECT_EYE, OBJECT_LOOK_AT),
    "rrt_skts": ("support", "level", SKT_EYE, SKT_LOOK_AT),
    "render_views": ("support", "level", SUPPORT_EYE, SUPPORT_LOOK_AT),
    "affordance_maps": ("support", "level", SUPPORT_EYE, SUPPORT_LOOK_AT),
    "sim_eval": ("trial", "method", SKT_EYE, SKT_LOOK_AT),
}
MAX_ITEMS = 5


def representatives(labels: dict[int, str], field: str, limit: int = MAX_ITEMS) -> list[int]:
    """Times of the first item for each value of ``field`` in the items' label tables."""
    seen, times = set(), []
    for t in sorted(labels):
        m = re.search(rf"^\| {re.escape(field)} \| (.+?) \|$", labels[t], re.MULTILINE)
        value = m.group(1) if m else None
        if value not in seen:
            seen.add(value)
            times.append(t)
    return times[:limit]


def _item_root(entity: str) -> str | None:
    """``/world/<kind>/<id>`` of an item entity, else None."""
    parts = entity.strip("/").split("/")
    return "/" + "/".join(parts[:3]) if len(parts) >= 3 and parts[0] == "world" \
        and parts[1] in ("supports", "objects", "trials") else None


def _stage_chunks(rrd: Path, stage: str, timeline: str, keep: dict[int, int], time_part: int):
    """The stage's static chunks and its ``timeline`` rows at the kept times (renumbered by
    ``keep``), clears and other timelines dropped, under ``/<stage>``, with fresh row ids;
    and the item roots of each new index."""
    reader = RrdReader(rrd)
    (store,) = reader.recordings()
    chunks, roots, counter = [], {}, 0
    for chunk in reader.stream(store=store).to_chunks():
        if chunk.timeline_names and timeline not in chunk.timeline_names:
            continue
        rb = chunk.to_record_batch()
        rows = np.ones(rb.num_rows, bool)
        if _CLEAR in rb.schema.names:
            rows &= np.asarray(rb.column(_CLEAR).is_null())
        if chunk.timeline_names:
            times = rb.column(timeline).to_pylist()
            rows &= np.array([t in keep for t in times])
        if not rows.any():
            continue
        rb = rb.filter(pa.array(rows))
        names = [n for n in rb.schema.names if n != _CLEAR
                 and (n not in chunk.timeline_names or n == timeline)]
        cols, fields = [], []
        for name in names:
            col, field = rb.column(name), rb.schema.field(name)
            if name == timeline:
                new = [keep[t] for t in col.to_pylist()]
                col = pa.array(new, col.type)
                root = _item_root(chunk.entity_path)
                for i in new:
                    if root:
                        roots.setdefault(i, set()).add(f"/{stage}{root}")
            elif name == _ROW_ID:
                col = pa.array([struct.pack(">QQ", time_part, counter + k)
                                for k in range(rb.num_rows)], pa.binary(16))
            cols.append(col)
            fields.append(field)
        meta = dict(rb.schema.metadata or {})
        meta[b"rerun:id"] = ("chunk_%016X%016x" % (time_part, counter)).encode()
        counter += rb.num_rows
        (new,) = Chunk.from_record_batch(pa.RecordBatch.from_arrays(
            cols, schema=pa.schema(fields, metadata=meta)))
        chunks.append(new.with_entity_path(f"/{stage}{chunk.entity_path}"))
    return chunks, roots


def review_blueprint(stages: list[str]) -> rrb.Blueprint:
    tabs = []
    for stage in stages:
        _, _, eye, look_at = REVIEW[stage]
        eye_controls = rrb.EyeControls3D(position=eye, look_target=look_at, eye_up=(0.0, 0.0, 1.0))
        view = rrb.Spatial3DView(origin=f"/{stage}/world", name=stage, eye_controls=eye_controls)
        info = rrb.TextDocumentView(origin=f"/{stage}/{INFO}", name="item")
        tabs.append(rrb.Horizontal(view, info, column_shares=[3, 1], name=stage))
    return rrb.Blueprint(rrb.Tabs(*tabs), rrb.BlueprintPanel(state="collapsed"),
                         rrb.SelectionPanel(state="collapsed"),
                         rrb.TimePanel(state="collapsed", timeline="support"))


def build_review(data_root: str | Path, out: str | Path) -> dict[str, int]:
    """Write the combined recording ``out`` from ``<data_root>/<stage>/<stage>.rrd`` for the
    stages of :data:`REVIEW` that exist; returns items kept per stage."""
    root = Path(data_root)
    stages = [s for s in REVIEW if (root / s / f"{s}.rrd").exists()]
    if not stages:
        raise FileNotFoundError(f"{root}: no stage recordings (run `make repro` first)")
    picked = {s: representatives(item_labels(root / s / f"{s}.rrd", REVIEW[s][0]), REVIEW[s][1])
              for s in stages}
    longest = {}  # per item timeline: the most representatives any stage on it has
    for s in stages:
        longest[REVIEW[s][0]] = max(longest.get(REVIEW[s][0], 0), len(picked[s]))
    kept = {}
    with recording("review", out, "review", review_blueprint(stages)) as rec:
        for n, stage in enumerate(stages):
            timeline, times = REVIEW[stage][0], picked[stage]
            rrd = root / stage / f"{stage}.rrd"
            chunks, roots = _stage_chunks(rrd, stage, timeline, {t: i for i, t in enumerate(times)},
                                          (1 << 58) + n)
            rr.send_chunks(chunks, recording=rec)
            # one item at a time, as in the stage recording; a stage with fewer
            # representatives than another on its timeline clears its last one after it
            last = len(times) + 1 if len(times) < longest[timeline] else len(times)
            for i in range(1, last):
                rec.reset_time()
                rec.set_time(timeline, sequence=i)
                for entity in sorted(roots.get(i - 1, ())):
                    rec.log(entity, rr.Clear(recursive=True))
            kept[stage] = len(times)
    return kept

