"""rrt_skts on the tiny dataset: contract, release near the hang, SKTs clear as executed."""

import dataclasses
import json

import numpy as np
import pytest

from skt_lib.config.params_file import load_params
from skt_lib.geometry.convex import box
from skt_lib.geometry.export import read_obj, write_shape
from skt_lib.geometry.se3 import invert, pose_matrix
from skt_lib.io import read_table
from skt_lib.planning.collision import MeshClearance
from skt_lib.planning.skts import (REACH_TOL_M, SktObject, _kp, _radius, approach_start, fill_failed,
                                   load_skt_tasks, mixed_attempts, plan_support_skts, sweep_clearance)
from skt_lib.geometry.skt import executed_path, resample
from skt_lib.schemas import CONTACTS, KEYPOINTS, OBJECTS, SKTS, SUPPORTS

pytestmark = pytest.mark.slow


def test_contract_goal_and_recheck_as_executed(tiny_dataset):
    params, data, reports = tiny_dataset
    p = load_params(params)
    m = json.loads((reports / "rrt_skts" / "metrics.json").read_text())
    for key in ("n_supports", "n_skts", "plan_success_rate", "reaches_hang_rate",
                "reaches_hang_rate_by_level", "recheck_collision_free_rate", "test_sweep_clear_rate",
                "failures_by_reason"):
        assert key in m
    assert m["plan_success_rate"] == m["reaches_hang_rate"] == m["n_skts"] / m["n_attempted"]
    assert m["recheck_collision_free_rate"] == 1.0
    skts = read_table(data / "rrt_skts" / "skts.parquet", SKTS)
    assert len(skts) == m["n_skts"] > 0
    contacts = read_table(data / "contact_sim" / "contacts.parquet", CONTACTS).set_index("item_id")
    kp = read_table(data / "rotation_extraction" / "keypoints.parquet", KEYPOINTS)
    kp = kp[kp["is_reference"]].iloc[0]
    k = pose_matrix(kp["position"], kp["quat"])
    supports = read_table(data / "mesh_gen" / "supports.parquet", SUPPORTS).set_index("support_id")
    ref = read_table(data / "mesh_gen" / "objects.parquet", OBJECTS).query("is_reference").iloc[0]
    (ref_mesh,) = read_obj(data / "mesh_gen" / ref["mesh_path"])
    radius = float(np.linalg.norm(ref_mesh.vertices - k[:3, 3], axis=1).max())
    for row in skts.itertuples():
        c = contacts.loc[row.support_id]
        goal = pose_matrix(c["hang_position"], c["hang_quat"]) @ k
        keypoints = np.stack(row.keypoints)
        # ξ_0 is the hanging keypoint, or at most the allowed offset from it (lifted, back
        # along the arrival): an SKT ends at the hang (within REACH_TOL_M)
        off = keypoints[0] - goal[:3, 3]
        assert np.linalg.norm(off) <= p.rrt_skts.max_release_offset_m + 1e-9 and off[2] >= -1e-9
        assert np.linalg.norm(off) <= REACH_TOL_M
        # dense: keypoint steps ≤ 1 mm
        assert np.linalg.norm(np.diff(keypoints, axis=0), axis=1).max() <= 0.001 + 1e-9
        # the SKT as sim_eval executes it (resampled to T, SKT frames) is collision-free for
        # the reference, by the independent mesh check — replayed here from the stored keypoints
        frames = executed_path(resample(keypoints, p.clustering.T), 0.001, radius)
        (sup_mesh,) = read_obj(data / "mesh_gen" / supports.loc[row.support_id, "mesh_path"])
        assert MeshClearance(sup_mesh, ref_mesh, 0.002).clearance(frames @ invert(k)) > 0
        # the stored reference poses are that executed path
        poses = np.stack([pose_matrix(q, r) for q, r in zip(row.positions, row.quats)])
        assert poses[0] == pytest.approx((frames @ invert(k))[-1], abs=1e-9)
        # starts in front of the hang
        assert keypoints[-1][0] > goal[0, 3] + p.rrt_skts.start_dx_m[0] - 1e-9


def test_test_supports_get_more_skts_with_the_same_first_ones(tiny_dataset):
    """A test support plans ``n_skts_per_test_support`` SKTs (the oracle's choices), other
    supports ``n_skts_per_support``; the support's generator draws them in order, so the
    first SKT is the same whichever count a split gets."""
    params, data, _ = tiny_dataset
    p = load_params(params)
    task = load_skt_tasks(data, p.common.seed, p.rrt_skts, p.clustering.T)[0]

    def plan(split: str, n_test: int) -> dict:
        rp = p.rrt_skts.model_copy(update={"n_skts_per_support": 1,
                                           "n_skts_per_test_support": n_test})
        return plan_support_skts(dataclasses.replace(task, split=split, params=rp, test_objects=()))

    one, train, test = plan("test", 1), plan("train", 3), plan("test", 3)
    assert one["n_attempted"] == train["n_attempted"] == 1
    assert test["n_attempted"] == 3 and len(test["plan_s"]) == 3
    assert one["skts"], "the tiny support should get an SKT"
    np.testing.assert_array_equal(test["skts"][0]["keypoints"], one["skts"][0]["keypoints"])
    np.testing.assert_array_equal(train["skts"][0]["keypoints"], one["skts"][0]["keypoints"])


def test_test_sweeps_split_at_the_final_approach_and_their_least_is_the_whole_sweep(tiny_dataset):
    """A test object's sweep is split where the keypoint comes within ``train_objects_from_m``
    of the hang for the last time; the least of the two parts is, bit for bit, the sweep of
    the whole executed path (what ``test_sweep_clear_rate`` has always measured)."""
    params, data, _ = tiny_dataset
    p = load_params(params)
    task = load_skt_tasks(data, p.common.seed, p.rrt_skts, p.clustering.T)[0]
    objects = task.train_objects  # standing in for test objects
    got = plan_support_skts(dataclasses.replace(task, split="test", test_objects=objects))
    assert len(got["test_sweeps"]) == len(objects) > 0
    (support_mesh,) = read_obj(task.support_mesh)
    hang = (pose_matrix(task.goal_position, task.goal_quat) @ _kp(task.reference))[:3, 3]
    waypoints = resample(got["skts"][0]["keypoints"], task.T)
    for o, w in zip(objects, got["test_sweeps"]):
        mesh, kp = read_obj(o.mesh)[0], _kp(o)
        frames = executed_path(waypoints, p.rrt_skts.recheck_step_m, _radius(mesh, kp))
        checker = MeshClearance(support_mesh, mesh, p.rrt_skts.recheck_spacing_m)

        def sweep(part):
            return sweep_clearance(checker, part, kp, p.rrt_skts.recheck_step_m)

        k = approach_start(frames, hang, p.rrt_skts.train_objects_from_m)
        assert 0 < k < len(frames)  # the tiny SKT starts farther out than that
        # each part is the sweep of its own frames, and their least is the whole sweep
        assert w["clearance_on_way_m"] == sweep(frames[:k])
        assert w["clearance_near_hang_m"] == sweep(frames[k:])
        assert w["clearance_m"] == sweep(frames) == min(w["clearance_on_way_m"],
                                                        w["clearance_near_hang_m"])


def test_approach_start_is_after_the_last_frame_far_from_the_hang():
    hang = np.array([0.1, 0.0, 0.0])
    xs = [0.30, 0.20, 0.12, 0.125, 0.20, 0.14, 0.13, 0.11, 0.10]  # in, out again, in for good
    frames = np.tile(np.eye(4), (len(xs), 1, 1))
    frames[:, 0, 3] = xs
    assert approach_start(frames, hang, 0.03) == 6  # 0.14 is the last one beyond 3 cm
    assert approach_start(frames[6:], hang, 0.03) == 0  # all within: all of it is the approach
    assert approach_start(frames, hang, 0.0) == len(xs) - 1  # only the hang itself


@pytest.mark.parametrize("checks", [
    {"probe_train_objects": True, "train_objects_from_m": 0.0, "penetration_tol_m": 0.0,
     "wall_train_objects": False},
    {"probe_train_objects": False, "wall_train_objects": True, "wall_from_m": 0.0},
    {"probe_train_objects": False, "wall_train_objects": True, "wall_from_m": 0.0, "planner": "per_skt"}],
    ids=["in the probe", "off the wall", "off the wall, a search per SKT"])
def test_a_support_no_training_object_clears_is_planned_for_the_reference_alone(tiny_dataset, tmp_path, checks):
    """With the training objects in the probe, or kept off the wall, a support none of their
    paths clears falls back to the reference alone: the same SKTs as planning without them
    (the failed pass draws nothing from the support's generator: its lead-in is blocked
    before the tree grows)."""
    params, data, _ = tiny_dataset
    p = load_params(params)
    task = next(t for t in load_skt_tasks(data, p.common.seed, p.rrt_skts, p.clustering.T))
    cube = box([0.0, 0.0, 0.0], [0.25, 0.25, 0.25])  # swallows support and wall wherever it goes
    write_shape(tmp_path / "cube", "cube", cube, [cube], 1.0, [0, 0, 0], np.eye(3) * 1e-3, (0, 1, 0, 1))
    blocker = SktObject("cube", str(tmp_path / "cube" / "visual.obj"),
                        str(tmp_path / "cube" / "collision.obj"), tuple(np.eye(4).ravel()))
    plain = plan_support_skts(dataclasses.replace(task, params=task.params.model_copy(
        update={"probe_train_objects": False, "wall_train_objects": False,
                "planner": checks.get("planner", task.params.planner)})))
    assert plain["probe"] == "reference" and plain["skts"]
    with_objects = dataclasses.replace(task, train_objects=(blocker,),
                                       params=task.params.model_copy(update=checks))
    got = plan_support_skts(with_objects)
    assert got["probe"] == "reference"
    n = len(got["plan_s"])  # every attempt planned again, as attempt n + i
    assert [s["index"] - n for s in got["skts"]] == [s["index"] for s in plain["skts"]]
    for a, b in zip(got["skts"], plain["skts"]):
        np.testing.assert_array_equal(a["keypoints"], b["keypoints"])
    assert got["failures"] == plain["failures"]  # the failed pass is not counted twice
    assert got["n_reference_fill"] == len(got["plan_s"]) and plain["n_reference_fill"] == 0


def test_fill_failed_replaces_only_the_failed_attempts_and_keeps_their_cost():
    path = np.zeros((3, 3))
    strict = [(0, path, None, 1.0, 10), (1, None, "no_path", 2.0, 20), (2, None, "stuck", 0.5, 5)]
    fallback = [(0, path + 1, None, 3.0, 30), (1, path + 2, None, 4.0, 40), (2, None, "no_path", 1.0, 7)]
    got, n = fill_failed(strict, fallback)
    assert n == 2 and len(got) == 3
    assert got[0] is strict[0]  # a strict SKT is kept as it is, first
    assert got[1][:3] == (4, fallback[1][1], None) and got[1][3:] == (6.0, 60)  # attempt 3 + 1
    assert got[2] == (5, None, "no_path", 1.5, 12)  # failed both ways: the fallback's reason
    assert fill_failed(strict, fallback[1:]) == (got, 2)  # the failed attempts' are enough
    with pytest.raises(KeyError):
        fill_failed(strict, fallback[:2])  # attempt 2's is missing


def test_mixed_attempts_put_the_objects_skts_first_and_the_references_behind():
    path = np.zeros((3, 3))
    objects = [(0, path, None, 1.0, 10), (1, None, "no_path", 2.0, 20)]
    # the reference's attempt 3 was filled (planned off the wall alone): attempt 4 + 3
    reference = [(i, path + i, None, 0.5, 5) for i in range(3)] + [(7, path + 3, None, 0.5, 5)]
    got, n = mixed_attempts(objects, reference, 4)
    assert n == 1
    assert got[0] is objects[0]  # the objects' SKT keeps its index: the oracle's first
    assert got[1:3] == [reference[2], reference[3]]  # the reference's beyond them, unchanged
    # the objects' failed attempt 1 becomes the reference's attempt 1, as attempt 4 + 1
    assert got[3][0] == 5 and got[3][1] is reference[1][1] and got[3][3:] == (2.5, 25)
    assert sorted(a[0] for a in got) == [0, 2, 5, 7]  # no index twice
    with pytest.raises(ValueError):  # the reference must hold every attempt
        mixed_attempts(objects, reference[:3], 4)
    with pytest.raises(ValueError):  # the objects plan no more attempts than there are
        mixed_attempts(reference, objects, 2)


def test_probe_on_test_supports_only_keeps_the_references_skts_behind_the_objects(tiny_dataset):
    """``probe_train_objects: test``: a test support's first ``n_skts_per_support`` SKTs are
    planned with the training objects, the rest are the reference's, byte for byte what
    planning without the objects gives; supports of other splits are planned as without."""
    params, data, _ = tiny_dataset
    p = load_params(params)
    base = p.rrt_skts.model_copy(update={"n_skts_per_support": 1, "n_skts_per_test_support": 2})
    tasks = load_skt_tasks(data, p.common.seed, base, p.clustering.T)
    test = next(t for t in tasks if t.split == "test")
    other = next(t for t in tasks if t.split != "test")
    mode = base.model_copy(update={"probe_train_objects": "test"})
    for task in (test, other):
        plain = plan_support_skts(task)
        got = plan_support_skts(dataclasses.replace(task, params=mode))
        if task is other:
            assert got["probe"] == plain["probe"] and got["n_reference_fill"] == 0
            assert [s["index"] for s in got["skts"]] == [s["index"] for s in plain["skts"]]
            for a, b in zip(got["skts"], plain["skts"]):
                np.testing.assert_array_equal(a["keypoints"], b["keypoints"])
            continue
        assert got["probe"].startswith("objects") and got["n_attempted"] == 2
        by_index = {s["index"]: s for s in got["skts"]}
        ref = {s["index"]: s for s in plain["skts"]}
        assert 1 in ref  # the tiny support's second SKT exists without the objects
        np.testing.assert_array_equal(by_index[1]["keypoints"], ref[1]["keypoints"])
        if got["n_reference_fill"]:  # the objects' attempt failed: the reference's 0 as 2
            np.testing.assert_array_equal(by_index[2]["keypoints"], ref[0]["keypoints"])
        else:  # planned with the objects: not the reference's SKT 0
            assert not np.array_equal(by_index[0]["keypoints"], ref[0]["keypoints"])
