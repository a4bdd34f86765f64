"""The threading route from a mesh's skeleton (skt_lib.planning.route) on generated hooks."""

import numpy as np
import pytest

from skt_lib.geometry.centreline import find_arms
from skt_lib.geometry.convex import union
from skt_lib.geometry.supports import FAMILIES, measure_difficulty
from skt_lib.planning.route import ROUTE_STEP_M, arm_route, route_sampler


def _j_hook(tiny_params, rise: float):
    shape = FAMILIES["j_hook"](np.random.default_rng(5), 0.004, False, rise, tiny_params.mesh_gen)
    mesh = union(shape.parts())
    hang = np.asarray(measure_difficulty(shape, tiny_params.mesh_gen).hang_point)
    return mesh, hang + [0.0, 0.0, 0.006]  # a keypoint 6 mm above the arm's centreline


def test_route_follows_the_arm_over_its_upturned_tip_and_on(tiny_params):
    mesh, kp = _j_hook(tiny_params, 0.05)
    arms = find_arms(mesh)
    route = arm_route(mesh, kp, 0.03, arms)
    assert route[0] == pytest.approx(kp, abs=1e-9)  # it starts at the hanging keypoint
    steps = np.linalg.norm(np.diff(route, axis=0), axis=1)
    assert steps.max() <= 3 * ROUTE_STEP_M  # continuous
    arm = min(arms, key=lambda a: np.linalg.norm(a.dense - kp, axis=1).min())
    tip_top = arm.dense[:, 2].max()
    assert route[:, 2].max() > tip_top  # up the upturned tip and past its top
    # along the arm the keypoint keeps its distance from the rod (parallel transport keeps
    # the offset's length): every route point before the run-on is 6 mm from the centreline
    on_arm = route[: -int(np.ceil(0.03 / ROUTE_STEP_M))]
    d = np.linalg.norm(on_arm[:, None] - arm.dense[None], axis=2).min(1)
    assert d == pytest.approx(np.full(len(d), 0.006), abs=0.0015)
    # the run-on is straight, 3 cm long
    run_on = route[-int(np.ceil(0.03 / ROUTE_STEP_M)) - 1:]
    assert np.linalg.norm(run_on[-1] - run_on[0]) == pytest.approx(0.03, abs=1e-6)


def test_route_sampler_draws_near_the_route_seeded():
    route = np.stack([np.linspace(0, 0.1, 101), np.zeros(101), np.zeros(101)], axis=1)
    sample = route_sampler(route, 0.002)
    a = np.stack([sample(np.random.default_rng(1)) for _ in range(3)])
    b = np.stack([sample(np.random.default_rng(1)) for _ in range(3)])
    assert np.array_equal(a, b)
    draws = np.stack([sample(g) for g in [np.random.default_rng(2)] for _ in range(2000)])
    assert draws[:, 1:].std() == pytest.approx(0.002, rel=0.1)
    assert 0.0 - 0.01 < draws[:, 0].min() and draws[:, 0].max() < 0.1 + 0.01
