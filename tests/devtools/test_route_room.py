"""tools/route_room.py: a ring carried along a hook's threading route at an SKT's frames.

A ring whose body hangs 7 cm below its keypoint, on the mesh zoo's pigtail (its curl's back
4.4 cm from the wall), must go through the wall on the curl's back, and moving its keypoint
across the rod cannot take all of it out; on a straight peg it has room all the way."""

import numpy as np
import pytest
import trimesh

from skt_lib.cli.mesh_zoo import WALL, _hook, pigtail
from skt_lib.geometry.convex import Mesh
from skt_lib.geometry.supports import _Path
from tools.route_room import route_room

pytestmark = pytest.mark.slow
#: The ring: major radius 3.5 cm, tube 4 mm, so its body reaches 7 cm below its keypoint.
R, r = 0.035, 0.004
NEED = 0.0005


def _mesh(tm: trimesh.Trimesh) -> Mesh:
    return Mesh(np.asarray(tm.vertices, float), np.asarray(tm.faces))


@pytest.fixture(scope="module")
def ring():
    """The torus (axis z, object frame) and its keypoint frame: at the top inside of its
    hole, x along the axis (the threading direction), z out of the ring's centre (up)."""
    kp = np.eye(4)
    kp[:3, :3] = np.array([[0.0, 0.0, 1.0], [0.0, -1.0, 0.0], [1.0, 0.0, 0.0]]).T
    kp[:3, 3] = [R - r, 0.0, 0.0]
    return _mesh(trimesh.creation.torus(R, r, major_sections=48, minor_sections=12)), kp


def test_on_the_pigtail_the_ring_goes_through_the_wall_on_the_curls_back(ring):
    mesh, kp = ring
    # where the pipeline's reference ring hangs on it (import-support's drop): 5 mm above the
    # arm's axis where the curl begins, clear of the curl's tip 14 mm beside it
    room = route_room(_mesh(pigtail()), mesh, kp, [0.0587, 0.0, 0.0025], NEED)
    assert np.all(np.diff(room.along_m) > 0) and room.along_m[0] == 0.0
    k = int(np.argmin(room.wall_m))
    assert room.wall_m[k] < -0.005  # through the wall by more than 5 mm ...
    assert room.clearance_m[k] <= room.wall_m[k] + 1e-9  # ... which the clearance counts
    assert 0.03 < room.along_m[k] < 0.09  # on the curl's back, not at the hang or past the tip
    assert not room.blocked[0]  # at the hang itself the ring has room
    assert room.blocked.any()  # moving the keypoint ≤ 12 mm across the rod does not free it
    assert np.all(room.room_m >= room.clearance_m - 1e-9)  # the route itself is one offset
    assert np.all(room.roll_deg[~room.blocked] == 0.0)


def test_on_a_straight_peg_the_ring_has_room_all_the_way(ring):
    mesh, kp = ring
    peg = _hook([_Path(WALL, 8).straight(0.09).array()], 0.004)
    on_peg = np.asarray(WALL) + 0.04 * np.array([np.cos(np.radians(8)), 0.0, np.sin(np.radians(8))])
    room = route_room(_mesh(peg), mesh, kp, on_peg + [0.0, 0.0, 0.006], NEED)  # 2 mm above it
    assert not room.blocked.any()
    assert room.clearance_m.min() > NEED and room.wall_m.min() > 0.0
    assert room.along_m[-1] > 0.05 + 0.02  # to the tip and on past it
