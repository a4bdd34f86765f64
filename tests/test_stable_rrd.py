"""Recordings are byte-reproducible across processes and still valid, complete recordings."""

import subprocess
import sys
from pathlib import Path

import numpy as np
from rerun.chunk import RrdReader

ROOT = Path(__file__).resolve().parents[1]

WRITER = """
import sys
import numpy as np
import rerun as rr
from viz.rerun_log import log_mesh, log_points, recording

with recording("demo", sys.argv[1], "demo title") as rec:
    rec.log("world/note", rr.TextDocument("first"), static=True)
    for i in range(40):
        rec.set_time("support", sequence=i)
        rec.log("world/cloud", rr.Points3D(np.random.default_rng(i).normal(size=(64, 3))))
        log_points(rec, f"world/p{i % 4}", np.full((2, 3), float(i)))
    log_mesh(rec, "world/m", np.eye(3), np.array([[0, 1, 2]]), (1, 0, 0, 1), level="easy")
    rec.log("world/note", rr.TextDocument("second"), static=True)
"""


def _write(path: Path) -> bytes:
    subprocess.run([sys.executable, "-c", WRITER, str(path)], cwd=ROOT, check=True,
                   capture_output=True)
    return path.read_bytes()


def test_recording_bytes_do_not_depend_on_the_process(tmp_path):
    a, b = _write(tmp_path / "a.rrd"), _write(tmp_path / "b.rrd")
    assert a == b
    done = subprocess.run([sys.executable, "-m", "rerun", "rrd", "verify", str(tmp_path / "a.rrd")],
                          capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-2000:]
    assert not list(tmp_path.glob(".*")), "temporary files left behind"


def test_stable_recording_keeps_data_order_and_blueprint(tmp_path):
    _write(tmp_path / "a.rrd")
    reader = RrdReader(tmp_path / "a.rrd")
    (rec,), (bp,) = reader.recordings(), reader.blueprints()
    assert rec.recording_id == "skt_hang-demo"
    assert bp.recording_id == "skt_hang-demo-blueprint"
    chunks = reader.stream(store=rec).to_chunks()
    timelines = {name for c in chunks for name in c.timeline_names}
    assert timelines == {"support"}  # no wall-clock log_time
    by_entity = {}
    for c in chunks:
        rb = c.to_record_batch()
        ids = [bytes(x) for x in rb.column("rerun.controls.RowId").to_pylist()]
        assert ids == sorted(ids) and len(set(ids)) == len(ids)
        by_entity.setdefault(c.entity_path, []).append(rb)
    (cloud,) = by_entity["/world/cloud"]
    assert cloud.column("support").to_pylist() == list(range(40))
    first = np.asarray(cloud.column("Points3D:positions")[3].as_py())
    assert np.allclose(first, np.random.default_rng(3).normal(size=(64, 3)).astype(np.float32))
    # "later log wins": the second static text has the larger row id.
    notes = [(bytes(rid), text) for rb in by_entity["/world/note"]
             for rid, text in zip(rb.column("rerun.controls.RowId").to_pylist(),
                                  rb.column("TextDocument:text").to_pylist())]
    assert [t for _, t in sorted(notes)] == [["first"], ["second"]]
