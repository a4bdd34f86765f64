"""The planner's probe: the reference keeps its clearance everywhere, the other objects are
checked only away from the hang when asked, and objects kept off the wall plane exactly."""

import numpy as np
from scipy.spatial.transform import Rotation

from skt_lib.geometry.convex import box
from skt_lib.geometry.export import write_shape
from skt_lib.geometry.se3 import invert
from skt_lib.planning.probe import ProbeObject, add_probe, make_probe_collision_fn, wall_points
from skt_lib.sim.world import World

from tests.planning.test_threading import PEG_R, _scene


def _collides_at(tmp_path, positions, **gate):
    """Verdicts of (ring only, ring + a 2 cm cube centred on the keypoint) at keypoint
    ``positions`` with the hanging orientation, on the toy peg."""
    _, _, k = _scene(tmp_path)
    cube = box([0, 0, 0], [0.01, 0.01, 0.01])
    write_shape(tmp_path / "cube", "cube", cube, [cube], 0.05, [0, 0, 0], np.eye(3) * 1e-5, (0, 1, 0, 1))
    hang = np.eye(4)
    hang[:3, 3] = [0.06, 0.0, PEG_R + 0.005 - k[2, 3]]  # the aperture 5 mm above the peg: the
    goal = hang @ k  # ring's convex parts (fuller than its mesh) clear it
    quat = Rotation.from_matrix(goal[:3, :3]).as_quat()
    out = []
    with World(1 / 240, 1, with_floor=False) as world:
        wall = world.add_wall()
        sup = world.load(str(tmp_path / "sup" / "sup.urdf"), np.eye(4), True, 0.5)
        ring = ProbeObject(str(tmp_path / "ring" / "collision.obj"), tuple(k.ravel()))
        both = add_probe(world, [ring, ProbeObject(str(tmp_path / "cube" / "collision.obj"),
                                                   tuple(np.eye(4).ravel()))])
        alone = add_probe(world, [ring])
        for probe, extra in ((alone, {}), (both, gate and {"hang": goal[:3, 3], **gate})):
            fn = make_probe_collision_fn(world, probe, [sup, wall], 0.0005, 0.005, **extra)
            out.append([fn(goal[:3, 3] + p, quat) for p in positions])
    return out


def test_other_objects_are_checked_only_away_from_the_hang(tmp_path):
    at_hang, along_peg = np.zeros(3), np.array([0.05, 0.0, 0.0])  # still around the peg
    ring, ring_and_cube = _collides_at(tmp_path, [at_hang, along_peg], others_from_m=0.03)
    assert ring == [False, False]  # the ring hangs free around the peg at both
    # the cube swallows the peg at both; within 3 cm of the hang the ring alone decides
    assert ring_and_cube == [False, True]


def test_without_a_hang_every_object_is_checked_everywhere(tmp_path):
    ring, ring_and_cube = _collides_at(tmp_path, [np.zeros(3), np.array([0.05, 0.0, 0.0])])
    assert ring == [False, False]
    assert ring_and_cube == [True, True]


def test_wall_points_give_the_least_x_of_every_vertex_at_any_frame():
    rng = np.random.default_rng(3)
    meshes = [box([0.02, 0.0, -0.05], [0.01, 0.03, 0.06]), box([0.0, 0.04, 0.0], [0.05, 0.005, 0.01])]
    keypoints = [np.eye(4), np.eye(4)]
    keypoints[1][:3, :3] = Rotation.random(random_state=1).as_matrix()
    keypoints[1][:3, 3] = [0.01, -0.02, 0.03]
    points = wall_points(list(zip(meshes, keypoints)))
    assert len(points) < 16  # hull vertices only: the boxes' inner corners are left out
    for _ in range(20):
        frame = np.eye(4)
        frame[:3, :3], frame[:3, 3] = Rotation.random(random_state=rng).as_matrix(), rng.normal(size=3)
        every = min((frame @ invert(k) @ np.c_[m.vertices, np.ones(8)].T)[0].min()
                    for m, k in zip(meshes, keypoints))
        assert np.isclose((points @ frame[0, :3]).min() + frame[0, 3], every, atol=1e-12)


def test_objects_kept_off_the_wall_beyond_wall_from_m(tmp_path):
    """The ring alone on the toy peg, with a 16 cm cube (not in the probe) kept off the wall:
    a pose collides exactly where the cube's least x is below 0, unless within
    ``wall_from_m`` of the hang."""
    _, _, k = _scene(tmp_path)
    cube = box([0, 0, 0], [0.08, 0.08, 0.08])
    hang = np.eye(4)
    hang[:3, 3] = [0.06, 0.0, PEG_R + 0.005 - k[2, 3]]
    goal = hang @ k
    quat = Rotation.from_matrix(goal[:3, :3]).as_quat()
    offsets = [np.array([dx, 0.0, 0.0]) for dx in (0.0, 0.005, 0.015, 0.05, 0.12)]
    crosses = [(goal[0, :3] @ cube.vertices.T).min() + goal[0, 3] + o[0] < 0 for o in offsets]
    assert crosses == [True, True, True, False, False]  # the cube reaches the wall near the hang
    with World(1 / 240, 1, with_floor=False) as world:
        obstacles = [world.load(str(tmp_path / "sup" / "sup.urdf"), np.eye(4), True, 0.5), world.add_wall()]
        probe = add_probe(world, [ProbeObject(str(tmp_path / "ring" / "collision.obj"), tuple(k.ravel()))])
        points = wall_points([(cube, np.eye(4))])
        everywhere = make_probe_collision_fn(world, probe, obstacles, 0.0005, 0.005, wall=points)
        gated = make_probe_collision_fn(world, probe, obstacles, 0.0005, 0.005, goal[:3, 3], 0.03,
                                        points, wall_from_m=0.01)
        ring_only = make_probe_collision_fn(world, probe, obstacles, 0.0005, 0.005)
        assert [ring_only(goal[:3, 3] + o, quat) for o in offsets] == [False] * 5
        assert [everywhere(goal[:3, 3] + o, quat) for o in offsets] == crosses
        assert [gated(goal[:3, 3] + o, quat) for o in offsets] == [False, False, True, False, False]
