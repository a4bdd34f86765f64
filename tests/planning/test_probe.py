"""The planner's probe: the reference keeps its clearance everywhere, the other objects are
checked only away from the hang when asked, and objects kept off the wall plane exactly."""

from contextlib import contextmanager

import numpy as np
from scipy.spatial.transform import Rotation

from skt_lib.geometry.convex import box
from skt_lib.geometry.export import read_obj, write_shape
from skt_lib.geometry.se3 import invert
import skt_lib.planning.probe as probe_module
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


def test_gated_queries_give_the_verdicts_of_querying_every_obstacle(tmp_path):
    """With ``probe_hull`` the probe skips the PyBullet queries of obstacles it cannot reach
    (its bounding sphere, then its hull's least x, against their boxes): every verdict must
    be the ungated one — on poses that sweep the band where PyBullet's 1 mm margin on convex
    meshes reports a clear pose as within the clearance, in front of the wall and beside the
    peg — and the gate must skip queries, or it saves nothing."""
    _, _, k = _scene(tmp_path)
    parts = read_obj(tmp_path / "ring" / "collision.obj")
    hull = wall_points([(part, k) for part in parts])
    rng = np.random.default_rng(7)
    rot = Rotation.random(400, random_state=rng).as_matrix()
    least_x = np.einsum("kj,nj->nk", hull, rot[:, 0, :]).min(axis=1)
    # in front of the wall: the hull's least x from 0 to 3 mm (clearance 0.5 mm + margin)
    at_wall = np.c_[-least_x + rng.uniform(0.0, 0.003, 400), rng.uniform(-0.1, 0.1, (400, 2))]
    # around the peg's tip and along it, and far off
    around = np.c_[rng.uniform(0.0, 0.3, 400), rng.uniform(-0.12, 0.12, (400, 2))]
    queries = []
    with World(1 / 240, 1, with_floor=False) as world:
        obstacles = [world.load(str(tmp_path / "sup" / "sup.urdf"), np.eye(4), True, 0.5), world.add_wall()]
        probe = add_probe(world, [ProbeObject(str(tmp_path / "ring" / "collision.obj"), tuple(k.ravel()))])
        every = make_probe_collision_fn(world, probe, obstacles, 0.0005, 0.0)
        gated = make_probe_collision_fn(world, probe, obstacles, 0.0005, 0.0, probe_hull=hull)
        verdicts = []
        for positions in (at_wall, around):
            for p, r in zip(positions, rot):
                q = Rotation.from_matrix(r).as_quat()
                with _counting(queries):
                    g = gated(p, q)
                verdicts.append((every(p, q), g))
    truth = [e for e, _ in verdicts]
    assert [g for _, g in verdicts] == truth
    assert 50 < sum(truth[:400]) < 350  # the wall band holds both verdicts
    assert sum(truth[400:]) > 20  # and so do the poses around the peg
    assert len(queries) < 0.6 * 2 * 800, len(queries)  # both obstacles on every pose: 1,600


@contextmanager
def _counting(calls: list):
    """Record every ``pybullet.getClosestPoints`` call made by the probe module meanwhile."""
    real = probe_module.pb.getClosestPoints

    def counted(*args, **kwargs):
        calls.append(args[1])
        return real(*args, **kwargs)

    probe_module.pb.getClosestPoints = counted
    try:
        yield
    finally:
        probe_module.pb.getClosestPoints = real
