"""run_trial end to end on a scene built in code (the reference ring, a straight peg angled
25° up from a wall plate): one trial that must succeed, one per failure reason, the floating
hand, and a check that an always-succeeding executor would fail these tests."""

import dataclasses

import numpy as np
import pytest

from skt_lib.geometry.se3 import invert
from skt_lib.sim import execute
from skt_lib.sim.execute import EXECUTORS, REASONS, run_trial
from skt_lib.sim.world import World
from tests.sim import scenes

pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    d = tmp_path_factory.mktemp("trial_scene")
    ring, vertices = scenes.build_ring(d)
    return scenes.write_support(d), ring, vertices


def _row(scene, positions, run=None, hand="panda", **changes):
    task = scenes.ring_task(*scene, positions, hand, **changes)
    row = (run or run_trial)(task)["row"]
    assert row["success"] == (row["failure_reason"] == "")
    assert row["failure_reason"] in ("", *REASONS)
    return row


# Each check takes the executor, so that the last test can hand them a fake one.
def check_success(scene, run=None):
    row = _row(scene, scenes.straight_skt(), run)
    assert row["success"], row
    assert row["n_executed"] == row["n_commands"] > 20  # the whole path ran
    assert row["max_track_err_m"] < 0.005 and row["touched_support"]
    assert row["grasp"].startswith("pitch") and row["blocked_by"] == ""


def check_path_through_support(scene, run=None):
    # the same line 9 mm lower: the ring's top section runs into the peg's tip
    row = _row(scene, scenes.straight_skt(offset=(0.0, 0.0, -0.009)), run)
    assert row["failure_reason"] == "collided_before_hang", row
    assert "object-support" in row["blocked_by"].split(",")
    assert 0 < row["n_executed"] < row["n_commands"]


def check_release_far_from_support(scene, run=None):
    # the same line 12 cm beside the peg: released in the air, it falls to the floor
    row = _row(scene, scenes.straight_skt(offset=(0.0, 0.12, 0.0)), run)
    assert row["failure_reason"] == "not_reached", row
    assert row["n_executed"] == row["n_commands"] and not row["touched_support"]
    assert row["detail"] == "predicate: touches_floor"  # let go: it fell


def check_unreachable(scene, run=None):
    row = _row(scene, scenes.straight_skt(offset=(0.0, 1.5, 0.0)), run)
    assert row["failure_reason"] == "ik_failed" and row["n_executed"] == 0, row
    assert "unreachable_hang" in row["detail"] and row["grasp"] == ""


def check_tracking_without_contact(scene, run=None):
    # a tolerance no controller meets: the error is not a collision, so it is ik_failed
    row = _row(scene, scenes.straight_skt(), run, track_tol_m=1e-4)
    assert row["failure_reason"] == "ik_failed" and row["blocked_by"] == "", row
    assert 0 < row["n_executed"] < row["n_commands"] and "tracking error" in row["detail"]


def check_floating_hand(scene, run=None):
    row = _row(scene, scenes.straight_skt(), run, hand="floating")
    assert row["success"] and row["n_executed"] == row["n_commands"], row
    assert row["max_track_err_m"] < 0.005
    # released in the air, the anchor is gone: nothing holds the object
    row = _row(scene, scenes.straight_skt(offset=(0.0, 0.12, 0.0)), run, hand="floating")
    assert row["failure_reason"] == "not_reached" and row["detail"] == "predicate: touches_floor", row


def test_ring_hangs_on_the_peg(scene):
    check_success(scene)


def test_path_through_the_support_collides_before_hang(scene):
    check_path_through_support(scene)


def test_release_far_from_the_support_is_not_reached(scene):
    check_release_far_from_support(scene)


def test_path_out_of_reach_fails_at_set_up(scene):
    check_unreachable(scene)


def test_tracking_error_without_contact_is_ik_failed(scene):
    check_tracking_without_contact(scene)


def test_floating_hand_carries_the_ring_and_lets_go(scene):
    check_floating_hand(scene)


def test_trials_repeat_exactly_whatever_ran_before(scene):
    task = scenes.ring_task(*scene, scenes.straight_skt(offset=(0.0, 0.12, 0.0)))
    a = run_trial(task)["row"]
    run_trial(scenes.ring_task(*scene, scenes.straight_skt(), "floating"))
    assert run_trial(task)["row"] == a


def test_an_always_succeeding_executor_fails_these_tests(scene):
    def always_success(task):
        return {"row": {"success": True, "failure_reason": "", "n_commands": 50, "n_executed": 50,
                        "max_track_err_m": 0.0, "touched_support": True, "blocked_by": "",
                        "grasp": "pitch45_roll0", "detail": ""}, "trace": []}

    check_success(scene, always_success)  # the fake passes the positive case …
    for check in (check_path_through_support, check_release_far_from_support, check_unreachable,
                  check_tracking_without_contact, check_floating_hand):
        with pytest.raises(AssertionError):  # … and fails every negative one
            check(scene, always_success)


def test_unknown_hand_is_an_error(scene):
    task = scenes.ring_task(*scene, scenes.straight_skt(), "gripper")
    with pytest.raises(ValueError, match="hand"):
        execute.run_trial(task)


def test_the_fast_executors_give_the_reference_executors_rows(scene):
    """The compiled IK, the Panda without visual meshes, the early end of a fallen object's
    perturbation and of an object's settle once at rest change how long a trial takes, not
    what it decides: the same row (to rounding in the tracking error) on a success, a
    collision, a fall and the floating hand; on the fall both fast executors stop early, on
    a success ``rest_exit`` ends the settle early and ``fallen_exit`` does not."""
    cases = [(scenes.straight_skt(), "panda"), (scenes.straight_skt(offset=(0.0, 0.0, -0.009)), "panda"),
             (scenes.straight_skt(offset=(0.0, 0.12, 0.0)), "panda"),
             (scenes.straight_skt(offset=(0.0, 0.12, 0.0)), "floating")]
    outcomes = set()
    for positions, hand in cases:
        task = dataclasses.replace(scenes.ring_task(*scene, positions, hand), record_every=24)
        runs = {ex: run_trial(dataclasses.replace(
                    task, settings=dataclasses.replace(task.settings, executor=ex)))
                for ex in EXECUTORS}
        errs = {ex: r["row"].pop("max_track_err_m") for ex, r in runs.items()}
        ref, fallen, rest = (runs[ex] for ex in EXECUTORS)
        assert ref["row"] == fallen["row"] == rest["row"]
        assert errs["fallen_exit"] == pytest.approx(errs["reference"], abs=1e-9)
        assert errs["rest_exit"] == errs["fallen_exit"]
        fell = ref["row"]["detail"] == "predicate: touches_floor"
        n = {ex: len(r["trace"]) for ex, r in runs.items()}
        if fell:
            assert n["fallen_exit"] == n["rest_exit"] < n["reference"] - 40
        else:
            assert n["fallen_exit"] == n["reference"]
        if ref["row"]["success"]:
            assert n["rest_exit"] < n["fallen_exit"] - 5  # the settle ended ≥ 120 steps early
        outcomes.add("success" if ref["row"]["success"] else ref["row"]["failure_reason"])
    assert {"success", "collided_before_hang"} <= outcomes


def test_an_unknown_executor_is_refused(scene):
    task = scenes.ring_task(*scene, scenes.straight_skt(), "panda")
    with pytest.raises(ValueError, match="executor: expected one of"):
        run_trial(dataclasses.replace(task, settings=dataclasses.replace(task.settings,
                                                                         executor="fast")))


def test_set_up_falls_back_to_an_alternative_skt(scene):
    """Out of reach on the task's SKT, the Panda's set-up runs the first alternative with a
    grasp and says so; with none, it is ik_failed naming how many were tried."""
    far = scenes.straight_skt(offset=(0.0, 1.5, 0.0))
    task = scenes.ring_task(*scene, far)
    ok = run_trial(dataclasses.replace(task, alternatives=(tuple(map(tuple, far)),
                                                            tuple(map(tuple, scenes.straight_skt())))))
    assert ok["row"]["success"] and ok["skt"] == 2, ok["row"]
    assert ok["row"]["grasp"].startswith("skt2/pitch")
    assert ok["row"]["n_commands"] == run_trial(scenes.ring_task(*scene, scenes.straight_skt()))["row"]["n_commands"]
    none = run_trial(dataclasses.replace(task, alternatives=(tuple(map(tuple, far)),)))
    assert none["row"]["failure_reason"] == "ik_failed" and none["skt"] == 0
    assert none["row"]["detail"].endswith("nor on any of 1 further SKTs")


@pytest.mark.parametrize("hand", ["panda", "floating"])
def test_set_up_prefers_an_alternative_the_object_sweeps_clear(scene, hand):
    """The task's own SKT runs the ring into the peg (collided_before_hang alone); given a
    clear alternative, set-up runs that one instead — with either hand."""
    into = scenes.straight_skt(offset=(0.0, 0.0, -0.009))
    assert _row(scene, into, hand=hand)["failure_reason"] == "collided_before_hang"
    task = dataclasses.replace(scenes.ring_task(*scene, into, hand),
                               alternatives=(tuple(map(tuple, scenes.straight_skt())),))
    out = run_trial(task)
    assert out["row"]["success"] and out["skt"] == 1, out["row"]
    assert out["row"]["grasp"].startswith("skt1/")


@pytest.mark.parametrize("hand", ["panda", "floating"])
def test_with_no_clear_alternative_set_up_runs_the_shallowest(scene, hand):
    """Where the object sweeps clear along none of the stored SKTs, set-up runs the one it
    penetrates least, not the first in order."""
    deep, shallow = (scenes.straight_skt(offset=(0.0, 0.0, dz)) for dz in (-0.012, -0.006))
    world_depth = {}
    for name, positions in (("deep", deep), ("shallow", shallow)):
        task = scenes.ring_task(*scene, positions, hand)
        with World(task.settings.dt, task.settings.solver_iterations) as world:
            world.add_wall()
            sup = world.load(task.support_urdf, np.eye(4), fixed=True, friction=0.5)
            kp = np.asarray(task.keypoint).reshape(4, 4)
            path = execute.executed_path(task.positions, task.settings.step_m, task.object_radius_m)
            obj = world.load(task.object_urdf, path[0] @ invert(kp), fixed=False, friction=0.5)
            world_depth[name] = execute._sweep_depth(world, obj, invert(kp), path, [sup])
    assert world_depth["deep"] > world_depth["shallow"] > execute.SWEEP_TOL_M, world_depth
    as_tuple = lambda p: tuple(map(tuple, p))  # noqa: E731
    task = dataclasses.replace(scenes.ring_task(*scene, deep, hand),
                               alternatives=(as_tuple(deep), as_tuple(shallow)))
    assert run_trial(task)["skt"] == 2


def test_unswept_alternatives_run_in_their_order(scene):
    """A learned method's fallbacks (``sweep_alternatives=False``) are tried in the order
    given, with no look at the simulated support: out of reach on its own SKT, the Panda runs
    the first fallback with a grasp even where a later one sweeps shallower — which the
    oracle's swept set-up would run."""
    far, deep, shallow = (tuple(map(tuple, scenes.straight_skt(offset=o)))
                          for o in ((0.0, 1.5, 0.0), (0.0, 0.0, -0.012), (0.0, 0.0, -0.006)))
    task = dataclasses.replace(scenes.ring_task(*scene, np.asarray(far)),
                               alternatives=(deep, shallow))
    assert run_trial(task)["skt"] == 2
    unswept = run_trial(dataclasses.replace(task, sweep_alternatives=False))
    assert unswept["skt"] == 1 and unswept["row"]["grasp"].startswith("skt1/"), unswept["row"]
