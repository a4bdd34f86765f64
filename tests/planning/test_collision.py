"""The re-check (MeshClearance) finds penetrations that only one of its parts can see:
support samples inside the object (reverse direction) and the wall plane x = 0."""

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from skt_lib.geometry.convex import box, union
from skt_lib.geometry.se3 import pose_matrix
from skt_lib.planning.collision import MeshClearance, surface_samples

SPACING = 0.003


def _ring():
    """A thick square ring in the x–y plane, object frame at its centre: bars 12 mm square
    in section, centreline half-size 24 mm."""
    h, w = 0.024, 0.006
    return union([box([0, h, 0], [h + w, w, w]), box([0, -h, 0], [h + w, w, w]),
                  box([h, 0, 0], [w, h - w, w]), box([-h, 0, 0], [w, h - w, w])])


def _forward_only(check, mesh, pose):
    """The object → support direction alone (object samples in the support), for the test's
    preconditions."""
    pts = surface_samples(mesh, SPACING) @ pose[:3, :3].T + pose[:3, 3]
    return check._support.signed_min(pts)


def test_rod_piercing_a_thick_ring_is_found_by_the_reverse_direction():
    # a 1.2 mm square rod along z at (0.152, 0.0005, ·), 40 mm long: through the ring's +y bar
    rod = box([0.152, 0.0005, 0.0], [0.0006, 0.0006, 0.02])
    ring = _ring()
    check = MeshClearance(rod, ring, SPACING)
    # the ring centred 24 mm along −y of the rod: its +y bar (12 mm thick) is pierced
    pierced = pose_matrix([0.15, -0.024, 0.0], [0, 0, 0, 1])
    # precondition: no ring sample lies inside the rod, so the forward direction is blind
    assert _forward_only(check, ring, pierced) >= 0
    assert check.clearance(pierced) < -0.004  # rod samples ≥ 4 mm deep inside the bar
    # the rod through the ring's hole: free, ≥ 15 mm from the bars (reported at the 6 mm cap)
    through_hole = pose_matrix([0.15, 0.0, 0.0], [0, 0, 0, 1])
    assert check.clearance(through_hole) == pytest.approx(0.006)
    # a batch reports its worst pose
    assert check.clearance(np.stack([through_hole, pierced])) == pytest.approx(
        check.clearance(pierced))


def test_thin_rod_inside_a_thick_bar_is_found_by_the_reverse_direction():
    # the rod entirely inside the object: nothing of the object is in the support at all
    rod = box([0.15, 0.0, 0.0], [0.002, 0.0005, 0.0005])
    ring = _ring()
    check = MeshClearance(rod, ring, SPACING)
    inside = pose_matrix([0.15, -0.024, 0.0], [0, 0, 0, 1])
    assert _forward_only(check, ring, inside) > 0.004
    assert check.clearance(inside) == pytest.approx(-0.0055, abs=3e-4)  # 6 mm half-bar − 0.5 mm


def test_object_behind_the_wall_is_found_by_the_wall_plane_only():
    support = box([0.2, 0.0, 0.0], [0.005, 0.005, 0.005])  # far from the object
    cube = box([0, 0, 0], [0.01, 0.01, 0.01])
    check = MeshClearance(support, cube, SPACING)
    behind = pose_matrix([0.004, 0.0, 0.0], [0, 0, 0, 1])  # 6 mm through the wall plane
    assert check.clearance(behind) == pytest.approx(-0.006, abs=1e-9)
    touching = pose_matrix([0.0101, 0.0, 0.0], [0, 0, 0, 1])
    assert check.clearance(touching) == pytest.approx(0.0001, abs=1e-9)
    free = pose_matrix([0.05, 0.0, 0.0], [0, 0, 0, 1])
    assert check.clearance(free) == pytest.approx(0.006)  # capped at 6 mm


def test_pruned_clearance_equals_moving_every_sample_bit_for_bit():
    """Cells out of reach are skipped (collision._Cells); the result must not move by a bit,
    on a sweep that goes from free through grazing into deep penetration, rotating."""
    rod = union([box([0.06, 0.0, 0.0], [0.06, 0.003, 0.003]),   # an arm out of the wall
                 box([0.118, 0.0, 0.02], [0.003, 0.003, 0.02])])  # and its upturned tip
    ring = _ring()
    check = MeshClearance(rod, ring, SPACING)
    rng, values = np.random.default_rng(3), []
    for trial in range(6):
        n = 60
        wall = trial >= 4  # the last two: beside the rod, toward and into the wall plane
        xs = np.linspace(0.05, 0.025, n) if wall else np.linspace(0.16, 0.06, n)
        poses = np.repeat(np.eye(4)[None], n, 0)
        poses[:, :3, :3] = Rotation.from_rotvec(
            np.outer(np.linspace(0, 1, n), rng.normal(0, 0.6, 3))).as_matrix()
        poses[:, :3, 3] = np.c_[xs, rng.normal(0, 0.004, n) + 0.024 * (trial % 2) + 0.08 * wall,
                                np.full(n, 0.002 * trial)]
        assert check.clearance(poses, chunk=17) == check.clearance_naive(poses)
        each = [(check.clearance(q), check.clearance_naive(q)) for q in poses]
        assert [f for f, _ in each] == [r for _, r in each], trial
        values += [r for _, r in each]
    # grazing poses too, not only deep ones and caps: where skipping decides
    assert min(values) < -0.003 and sum(0 < v < 0.006 for v in values) > 20


def test_step_bounded_clearance_is_the_minimum_over_every_pose_bit_for_bit():
    """With a bound on how far the object moves per pose, clearance evaluates fewer poses
    (a Lipschitz bound between evaluated ones) and must still return the exact minimum over
    all of them — on executed sweeps that pass free, graze and penetrate; and it must skip
    poses, or it saves nothing."""
    from skt_lib.geometry.skt import executed_path

    rod = box([0.06, 0.0, 0.0], [0.06, 0.003, 0.003])  # an arm out of the wall
    ring = _ring()
    check = MeshClearance(rod, ring, SPACING)
    radius = float(np.linalg.norm(ring.vertices, axis=1).max())
    rng, evaluated, total, n_all, values = np.random.default_rng(5), [], 0, 0, []
    real = check.per_pose
    check.per_pose = lambda poses, chunk=128: (evaluated.append(len(poses)), real(poses, chunk))[1]
    for trial in range(8):
        # the ring (flat) slides in over the arm: grazing it (even trials) or pressed into it
        z = 0.0095 + 0.0006 * trial if trial % 2 == 0 else 0.005
        knots = np.c_[np.linspace(0.2, 0.07, 5), rng.normal(0, 0.001, 5),
                      z + rng.normal(0, 0.0003, 5)]
        poses = executed_path(knots, 0.001, radius)
        evaluated.clear()
        fast = check.clearance(poses, max_step_m=0.001)
        total += sum(evaluated)
        full = float(real(poses).min())
        assert fast == full == check.clearance(poses), trial
        n_all, values = n_all + len(poses), values + [fast]
    assert min(values) < 0 < max(values) < 0.006  # penetrating and grazing sweeps
    assert total < 0.8 * n_all, (total, n_all)  # 0.72 measured: a straight arm grazed end to end


def test_step_bounds_hold_every_sample_and_are_tight():
    """:meth:`MeshClearance.step_bounds` must bound how far every object sample moves from
    one pose to the next (the refinement's skipping rests on it), and should not be loose:
    for a turn about the object's frame origin, the vertex at its radius moves almost as far."""
    ring = _ring()
    check = MeshClearance(box([0.2, 0.0, 0.0], [0.005, 0.005, 0.005]), ring, SPACING)
    rng = np.random.default_rng(11)
    n = 200
    poses = np.repeat(np.eye(4)[None], n, 0)
    poses[:, :3, :3] = Rotation.from_rotvec(np.cumsum(rng.normal(0, 0.02, (n, 3)), axis=0)).as_matrix()
    poses[:, :3, 3] = np.cumsum(rng.normal(0, 0.0005, (n, 3)), axis=0)
    pts = surface_samples(ring, SPACING)
    moved = np.einsum("nij,kj->nki", poses[:, :3, :3], pts) + poses[:, None, :3, 3]
    actual = np.linalg.norm(np.diff(moved, axis=0), axis=2).max(axis=1)
    bound = check.step_bounds(poses)
    assert np.all(actual <= bound)
    # turning about z alone: the ring's corners, nearly as far from z as from the origin,
    # sweep nearly the whole bound
    turn = np.repeat(np.eye(4)[None], n, 0)
    turn[:, :3, :3] = Rotation.from_rotvec(np.outer(np.cumsum(rng.uniform(0.001, 0.05, n)),
                                                    [0.0, 0.0, 1.0])).as_matrix()
    far = np.linalg.norm(np.diff(np.einsum("nij,kj->nki", turn[:, :3, :3], ring.vertices), axis=0),
                         axis=2).max(axis=1)
    assert np.all(far <= check.step_bounds(turn)) and np.all(check.step_bounds(turn) < 1.02 * far)
