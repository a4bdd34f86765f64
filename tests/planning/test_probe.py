"""The planner's probe: the reference keeps its clearance everywhere, the other objects are
checked only away from the hang when asked."""

import numpy as np
from scipy.spatial.transform import Rotation

from skt_lib.geometry.convex import box
from skt_lib.geometry.export import write_shape
from skt_lib.planning.probe import ProbeObject, add_probe, make_probe_collision_fn
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
