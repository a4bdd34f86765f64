"""The URDF chain's kinematics against PyBullet's, and the bounded IK."""

import numpy as np
import pytest

from skt_lib.geometry.se3 import pose_matrix
from skt_lib.sim.kinematics import Chain, IKSettings, rotation_error
from skt_lib.sim.robot import FINGER_OPEN_M, PANDA_URDF, REST_Q, Panda
from skt_lib.sim.world import World

BASE = pose_matrix([0.15, 0.0, 0.3], [0, 0, 0, 1])


@pytest.fixture(scope="module")
def chain():
    return Chain(PANDA_URDF, "panda_grasptarget", BASE)


def test_forward_kinematics_equal_pybullets(chain):
    rng = np.random.default_rng(0)
    with World(1 / 240, 50, with_floor=False) as world:
        robot = Panda(world, BASE)
        assert chain.names == [f"panda_joint{i}" for i in range(1, 8)]
        for _ in range(50):
            q = rng.uniform(chain.lower, chain.upper)
            robot.reset(q, FINGER_OPEN_M)
            assert np.abs(chain.fk(q) - robot.grasp_world()).max() < 1e-6


def test_jacobian_equals_finite_differences(chain):
    rng = np.random.default_rng(1)
    for _ in range(5):
        q = rng.uniform(chain.lower, chain.upper)
        t, jac = chain.fk_jacobian(q)
        assert np.allclose(t, chain.fk(q))
        num = np.empty((6, 7))
        for i in range(7):
            dq = np.zeros(7)
            dq[i] = 1e-6
            t2 = chain.fk(q + dq)
            num[:3, i] = (t2[:3, 3] - t[:3, 3]) / 1e-6
            num[3:, i] = rotation_error(t2[:3, :3], t[:3, :3]) / 1e-6
        assert np.abs(jac - num).max() < 1e-5


def test_rotation_error_is_the_rotation_vector_up_to_pi():
    for angle in (1e-7, 0.3, 2.0, np.pi - 1e-6, np.pi):
        axis = np.array([1.0, -2.0, 0.5]) / np.linalg.norm([1.0, -2.0, 0.5])
        k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
        r = np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k
        err = rotation_error(r, np.eye(3))
        assert np.linalg.norm(err) == pytest.approx(angle, abs=1e-6)
        assert abs(abs(err @ axis) - angle) < 1e-6  # along ±axis (± only at π)


def test_ik_solves_within_the_limits(chain):
    """Random reachable targets from the rest pose, a third of them with joints at their
    limits: solved to 0.1 mm / 1 mrad, never outside a limit. Clipping a free solution
    onto the limits instead leaves those with joints on a limit millimetres off."""
    rng = np.random.default_rng(2)
    solved, at_limit_solved, n_at_limit = 0, 0, 0
    for i in range(60):
        q_true = rng.uniform(chain.lower, chain.upper)
        if i % 3 == 0:  # two joints on a limit
            for j in rng.choice(7, 2, replace=False):
                q_true[j] = chain.lower[j] if rng.random() < 0.5 else chain.upper[j]
            n_at_limit += 1
        target = chain.fk(q_true)
        # start near the answer (as when tracking a path) ...
        q, d, a = chain.solve(target, q_true + rng.normal(0, 0.05, 7), settings=IKSettings())
        assert (q >= chain.lower).all() and (q <= chain.upper).all()
        ok = d <= 1e-4 and a <= 1e-3
        solved += ok
        at_limit_solved += ok and i % 3 == 0
    assert solved == 60 and at_limit_solved == n_at_limit
    # ... and from the rest pose, far away: most converge
    hits = 0
    for _ in range(40):
        target = chain.fk(rng.uniform(chain.lower, chain.upper))
        _, d, a = chain.solve(target, np.asarray(REST_Q), settings=IKSettings(max_iterations=100))
        hits += d <= 1e-4 and a <= 1e-3
    assert hits >= 28


def test_chain_refuses_a_missing_link():
    with pytest.raises(ValueError, match="no joint leads to link 'nope'"):
        Chain(PANDA_URDF, "nope")


def test_the_compiled_solve_equals_the_numpy_reference(chain):
    """The numba kernel (what set-up runs) against the numpy solve (the reference executor's
    IK), far starts and tracking starts, joints on their limits included: the same joints."""
    numpy_chain = Chain(PANDA_URDF, "panda_grasptarget", BASE, compiled=False)
    assert chain.compiled and not numpy_chain.compiled
    rng = np.random.default_rng(3)
    for i in range(40):
        q_true = rng.uniform(chain.lower, chain.upper)
        q_true[i % 7] = chain.upper[i % 7] if i % 2 else chain.lower[i % 7]
        start = np.asarray(REST_Q) if i % 4 == 0 else q_true + rng.normal(0, 0.1, 7)
        settings = IKSettings(max_iterations=100, rest_gain=0.05 * (i % 2))
        q, d, a = chain.solve(chain.fk(q_true), start, settings=settings)
        q_ref, d_ref, a_ref = numpy_chain.solve(chain.fk(q_true), start, settings=settings)
        assert np.abs(q - q_ref).max() < 1e-8
        assert d == pytest.approx(d_ref, abs=1e-10) and a == pytest.approx(a_ref, abs=1e-9)


def test_track_equals_one_solve_per_pose_bit_for_bit(chain):
    """Joint paths along smooth joint-space curves (tracked, off tolerance, jumping): the
    one-call compiled tracker gives the very bits of a compiled solve per pose
    (``track_naive``), and the same failure."""
    settings = IKSettings(max_iterations=20, rest_gain=0.05)
    mid = (chain.lower + chain.upper) / 2.0
    rng = np.random.default_rng(4)
    outcomes = set()
    for i in range(12):
        a, b = rng.uniform(chain.lower, chain.upper, (2, 7))
        if i % 3 == 2:
            b = a + rng.normal(0, 0.3, 7)  # short: tracked all the way
        s = np.linspace(0.0, 1.0, 60)[:, None]
        targets = np.stack([chain.fk(q) for q in a + s * (b - a)])
        q0, _, _ = chain.solve(targets[0], a, settings=IKSettings(max_iterations=100))
        for tol_m, jump in ((2e-3, 0.2), (2e-3, 0.02), (1e-9, 0.2)):
            path, fail = chain.track(targets[1:], q0, mid, settings, tol_m, 0.02, jump)
            ref_path, ref_fail = chain.track_naive(targets[1:], q0, mid, settings, tol_m, 0.02,
                                                   jump)
            assert fail == ref_fail
            assert path.shape == ref_path.shape and np.array_equal(path, ref_path)
            outcomes.add(None if fail is None else fail[0])
    assert outcomes == {None, "tracking_tolerance", "joint_jump"}
