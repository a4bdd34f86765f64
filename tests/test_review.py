"""Recordings made for review: one item at a time on each item timeline, labelled; and, where a
browser is installed, what Rerun's web viewer actually draws."""

from collections import Counter
from pathlib import Path

import pytest

from viz.recording_query import item_labels, visible_entities
from viz.screenshot import missing_tools

MISSING = missing_tools(ocr=True)  # checked before the fixtures run: skipping costs nothing

# stage: {item timeline: entity prefix of the items}
ITEM_RECORDINGS = {
    "mesh_gen": {"support": "/world/supports/", "object": "/world/objects/"},
    "contact_sim": {"support": "/world/supports/", "object": "/world/objects/"},
    "rotation_extraction": {"object": "/world/objects/"},
    "rrt_skts": {"support": "/world/supports/"},
    "render_views": {"support": "/world/supports/"},
    "affordance_maps": {"support": "/world/supports/"},
    "sim_eval": {"trial": "/world/trials/"},
}


def _rrd(tiny_dataset, tiny_evaluated, stage: str) -> Path:
    data = tiny_evaluated[2].parent if stage == "sim_eval" else tiny_dataset[1]
    return data / stage / f"{stage}.rrd"


def _item(entity: str, prefix: str) -> str | None:
    return entity[len(prefix):].split("/")[0] if entity.startswith(prefix) else None


@pytest.mark.parametrize("stage", sorted(ITEM_RECORDINGS))
def test_each_time_of_an_item_timeline_shows_exactly_one_labelled_item(stage, tiny_dataset,
                                                                        tiny_evaluated):
    rrd = _rrd(tiny_dataset, tiny_evaluated, stage)
    for timeline, prefix in ITEM_RECORDINGS[stage].items():
        shown = visible_entities(rrd, timeline)
        labels = item_labels(rrd, timeline)
        assert len(shown) >= 2, f"{stage}/{timeline}: {len(shown)} items"
        assert sorted(shown) == list(range(len(shown))) == sorted(labels)
        items = []
        for t, entities in shown.items():
            present = {i for e in entities if (i := _item(e, prefix))}
            assert len(present) == 1, f"{stage}/{timeline}@{t}: items {sorted(present)}"
            (item,) = present
            if timeline == "trial":  # trial n of the recording is shown at time n
                assert item == f"{t:02d}", (t, item)
            else:  # supports and objects are named by their id in the label
                assert item in labels[t].splitlines()[0], (t, item, labels[t][:80])
            items.append(item)
        assert len(set(items)) == len(items), f"{stage}/{timeline}: an item shown twice: {items}"


@pytest.mark.browser
@pytest.mark.skipif(bool(MISSING), reason=f"no browser screenshots here: missing {', '.join(MISSING)}")
@pytest.mark.parametrize("stage", ["mesh_gen", "render_views", "affordance_maps", "rrt_skts",
                                   "sim_eval"])
def test_web_viewer_draws_the_last_item_with_its_label(stage, tiny_dataset, tiny_evaluated,
                                                       tmp_path):
    from viz.screenshot import read_text, screenshot, squash

    rrd = _rrd(tiny_dataset, tiny_evaluated, stage)
    timeline = next(iter(ITEM_RECORDINGS[stage]))
    labels = item_labels(rrd, timeline)
    title = labels[max(labels)].splitlines()[0].lstrip("# ")
    shot = screenshot(rrd, tmp_path / "shot.png")
    # The viewer opens at the end of the timeline: the last item, alone and framed.
    assert shot.view_fill >= 0.01, f"3D view nearly empty ({shot.view_fill:.4f})"
    text = squash(read_text(shot.path))
    key = title.split(":")[0].split("/")[1:] if stage == "sim_eval" else [title]
    assert all(squash(k) in text for k in key), f"label {title!r} not read in {text[:300]!r}"


def test_representatives_take_the_first_item_of_each_value():
    from viz.rerun_log import item_markdown
    from viz.review_recording import representatives

    levels = ["easy", "easy", "hard", "normal", "hard", "very_hard", "normal"]
    labels = {t: item_markdown(f"support_{t:05d}", {"level": lv, "family": "peg"})
              for t, lv in enumerate(levels)}
    assert representatives(labels, "level") == [0, 2, 3, 5]
    assert representatives(labels, "level", limit=2) == [0, 2]
    assert representatives(labels, "family") == [0]


def test_distance_to_path_is_to_the_polyline_not_its_vertices():
    import numpy as np

    from viz.rollouts import distance_to_path

    path = np.array([[0.0, 0, 0], [1.0, 0, 0], [1.0, 1.0, 0]])
    assert distance_to_path(np.array([0.5, 0.2, 0.0]), path) == pytest.approx(0.2)
    assert distance_to_path(np.array([1.3, 0.5, 0.0]), path) == pytest.approx(0.3)
    assert distance_to_path(np.array([-1.0, 0.0, 0.0]), path) == pytest.approx(1.0)
    assert distance_to_path(np.array([2.0, 2.0, 2.0]), path[:1]) == pytest.approx(np.sqrt(12))


def test_combined_review_has_each_stage_one_representative_at_a_time(tiny_dataset,
                                                                      tiny_evaluated, tmp_path):
    import subprocess
    import sys

    from viz.review_recording import REVIEW, build_review

    root = tmp_path / "data"
    root.mkdir()
    for stage in REVIEW:
        (root / stage).symlink_to(_rrd(tiny_dataset, tiny_evaluated, stage).parent)
    kept = build_review(root, tmp_path / "review.rrd")
    assert set(kept) == set(REVIEW) and all(n >= 2 for n in kept.values()), kept
    done = subprocess.run([sys.executable, "-m", "rerun", "rrd", "verify",
                           str(tmp_path / "review.rrd")], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-2000:]
    for timeline in ("support", "object", "trial"):
        stages = [s for s, spec in REVIEW.items() if spec[0] == timeline]
        shown = visible_entities(tmp_path / "review.rrd", timeline)
        assert sorted(shown) == list(range(max(kept[s] for s in stages)))
        for t, entities in shown.items():
            for stage in stages:
                prefix = f"/{stage}{ITEM_RECORDINGS[stage][timeline]}"
                present = {i for e in entities if (i := _item(e, prefix))}
                assert len(present) == (1 if t < kept[stage] else 0), (stage, t, present)
    # representatives: one per difficulty level, object category, method
    for stage, (timeline, field, _, _) in REVIEW.items():
        labels = item_labels(tmp_path / "review.rrd", timeline, f"/{stage}/item/info")
        values = [next(line for line in text.splitlines() if line.startswith(f"| {field} |"))
                  for text in labels.values()]
        assert len(labels) == kept[stage] and len(set(values)) == len(values), (stage, values)


def _pose(t):
    import rerun as rr

    return rr.Transform3D(translation=t[:3, 3], mat3x3=t[:3, :3])


def _rows(rrd: Path) -> Counter:
    """A recording's rows as a multiset of (entity, times, non-empty component values): what
    it shows, whatever the chunking and row order within a time."""
    from rerun.chunk import RrdReader

    reader = RrdReader(rrd)
    (store,) = reader.recordings()
    out = Counter()
    for chunk in reader.stream(store=store).to_chunks():
        rb = chunk.to_record_batch()
        cols = {n: rb.column(n).to_pylist() for n in rb.schema.names if n != "rerun.controls.RowId"}
        for i in range(rb.num_rows):
            times = tuple((n, cols[n][i]) for n in chunk.timeline_names)
            vals = tuple(sorted((c, repr(v[i])) for c, v in cols.items()
                                if c not in chunk.timeline_names and v[i] not in (None, [])))
            out[chunk.entity_path, times, vals] += 1
    return out


def test_rollout_trace_columns_are_the_per_step_logs(tmp_path):
    """The trace of a rollout, sent as columns, holds row for row what logging each recorded
    step (robot links, object, keypoint trail, distance plot) would hold — the links only
    while the arm is in the scene (it leaves after the retreat: ``links`` None)."""
    import numpy as np
    import rerun as rr
    from scipy.spatial.transform import Rotation

    from skt_lib.sim.world import World
    from viz.rerun_log import log_strip, recording
    from viz.rollouts import _log_trace, distance_to_path

    rng = np.random.default_rng(0)

    def pose():
        t = np.eye(4)
        t[:3, :3] = Rotation.random(random_state=rng).as_matrix()  # not symmetric: order shows
        t[:3, 3] = rng.normal(size=3)
        return t

    frames = [{"step": 3 * i, "links": {1: pose(), 4: pose()} if i < 4 else None,
               "object": pose()} for i in range(6)]
    keypoint, skt = pose(), rng.normal(size=(5, 3))
    n, step, name = 2, 100, "world/trials/02"
    with recording("test", tmp_path / "columns.rrd", "t") as rec:
        rec.set_time("trial", sequence=n)
        _log_trace(rec, name, n, step, frames, [1, 4], keypoint, skt)
    with recording("test", tmp_path / "steps.rrd", "t") as rec:
        rec.set_time("trial", sequence=n)
        trail = []
        for f in frames:
            rec.set_time("step", sequence=step + f["step"])
            for k in (1, 4) if f["links"] is not None else ():
                t = World.to_support(f["links"][k])
                rec.log(f"world/robot/link_{k}", _pose(t))
            t = f["object"]
            rec.log(f"{name}/object", _pose(t))
            trail.append((t @ keypoint)[:3, 3])
            log_strip(rec, f"{name}/keypoint_trail", np.asarray(trail), rgb=(250, 250, 250))
            rec.log("plots/keypoint_to_skt_mm/02",
                    rr.Scalars(1000 * distance_to_path(trail[-1], skt)))
    columns, steps = _rows(tmp_path / "columns.rrd"), _rows(tmp_path / "steps.rrd")
    assert sum(columns.values()) == 6 * 3 + 4 * 2
    assert columns == steps


def test_each_trial_plots_its_own_distance_series(tmp_path):
    """Two trials' distance plots are two series (entities), so the plot draws no line from
    one trial's end to the next one's start."""
    import numpy as np

    from viz.rerun_log import recording
    from viz.rollouts import _log_trace

    frames = [{"step": i, "links": {}, "object": np.eye(4)} for i in range(3)]
    with recording("test", tmp_path / "two.rrd", "t") as rec:
        for n, step in ((0, 0), (1, 50)):
            _log_trace(rec, f"world/trials/{n:02d}", n, step, frames, None, np.eye(4),
                       np.array([[0.0, 0.0, 0.1 * (n + 1)], [0.1, 0.0, 0.1 * (n + 1)]]))
    plots = {}
    for (entity, times, _), count in _rows(tmp_path / "two.rrd").items():
        if entity.startswith("/plots"):
            plots.setdefault(entity, set()).update(t for name, t in times if name == "trial")
    assert plots == {"/plots/keypoint_to_skt_mm/00": {0}, "/plots/keypoint_to_skt_mm/01": {1}}


def test_the_arm_is_hidden_from_when_it_leaves_the_scene(tmp_path):
    """A Panda trial shows its arm until the first recorded step without it (it leaves after
    the retreat), and the final state the ``trial`` timeline shows has none; a trial that
    ends with the arm in the scene (blocked on the way in) shows it to the end; a
    floating-hand trial never shows it."""
    from types import SimpleNamespace

    import numpy as np
    import trimesh

    from viz.rollouts import log_rollouts, robot_meshes

    links = list(robot_meshes((0.15, 0.0, 0.3)))
    box = trimesh.creation.box((0.01, 0.01, 0.01))
    replay = []
    for n, (panda, leaves) in enumerate(((True, 3), (True, None), (False, None))):
        task = SimpleNamespace(trial_id=f"t{n}", method="oracle", support_id="s", object_id="o",
                               alternatives=(), positions=((0, 0, 0), (0.1, 0, 0)),
                               keypoint=tuple(np.eye(4).ravel()))
        row = {"success": n == 2, "failure_reason": "" if n == 2 else "dropped", "difficulty": "easy",
               "category": "mug", "grasp": "g", "max_track_err_m": 0.0, "detail": ""}
        frames = [{"step": 4 * i, "object": np.eye(4),
                   "links": {k: np.eye(4) for k in links}
                   if panda and (leaves is None or i < leaves) else None} for i in range(5)]
        replay.append((task, {"row": row, "trace": frames}))
    log_rollouts(tmp_path / "r.rrd", replay, {"s": box}, {"o": box}, (0.15, 0.0, 0.3))
    import ast

    scales = sorted((dict(times)["trial"], dict(times)["step"],
                     ast.literal_eval(dict(vals)["Transform3D:scale"])[0][0])
                    for (entity, times, vals), _ in _rows(tmp_path / "r.rrd").items()
                    if entity == "/world/robot")
    # the failures (Panda) are replayed first: the first shown from its start, hidden
    # (micrometre-sized: the viewer ignores a zero scale) from its step 12, where the arm has
    # left; the second shown throughout; the floating-hand trial, after them and the gaps,
    # hidden throughout
    assert [(t, s, scale == 1.0 or scale < 1e-5) for t, s, scale in scales] == \
        [(0, 0, True), (0, 12, True), (1, 66, True), (2, 132, True)], scales
    assert [scale == 1.0 for *_, scale in scales] == [True, False, True, False], scales


def test_rrt_skts_recording_draws_at_most_eight_skts_per_support(tmp_path):
    """The paper preset's 50 SKTs per support would overflow Rerun's reader; the first 8 are
    drawn and the item says so; a support with fewer is drawn whole, its label unchanged."""
    import numpy as np
    import pandas as pd
    import trimesh

    from viz.recording_query import item_labels
    from viz.rrt_skts_report import MAX_DRAWN_SKTS, log_skts

    box = trimesh.creation.box((0.05, 0.05, 0.1))
    rng = np.random.default_rng(0)
    counts = {"support_00000": 12, "support_00001": 3}
    results = [{"support_id": sid, "n_attempted": n, "failures": {}, "skts": [
        {"index": k, "keypoints": np.cumsum(rng.normal(0, 0.005, (20, 3)), 0),
         "min_clearance_m": 0.001, "poses": [np.eye(4), np.eye(4)]} for k in range(n)]}
        for sid, n in counts.items()]
    supports = pd.DataFrame({"difficulty": ["easy", "hard"], "family": ["j", "l"]},
                            index=list(counts))
    log_skts(tmp_path / "r.rrd", results, supports, {s: box for s in counts}, box)
    drawn = {}
    for (entity, _, _), _ in _rows(tmp_path / "r.rrd").items():
        parts = entity.split("/")
        if "skt" in parts and parts[-1] != "waypoints":
            sid = next(p for p in parts if p.startswith("support_"))
            drawn.setdefault(sid, set()).add(int(parts[parts.index("skt") + 1]))
    assert MAX_DRAWN_SKTS == 8
    assert drawn == {"support_00000": set(range(8)), "support_00001": {0, 1, 2}}
    labels = item_labels(tmp_path / "r.rrd", "support")
    assert "the first 8" in labels[0] and "drawn" not in labels[1]
