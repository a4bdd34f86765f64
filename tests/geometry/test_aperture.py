"""The aperture of a flat ring comes out along the ring's axis: the 90 %-cone estimate is
snapped to the shape's principal axis when that lies within 10° and admits the rod."""

import numpy as np
import trimesh

from skt_lib.cli.mesh_zoo import scissors
from skt_lib.geometry.aperture import find_aperture
from skt_lib.geometry.convex import Mesh
from skt_lib.geometry.repair import repair


def _aperture(tm: trimesh.Trimesh):
    mesh = repair(Mesh(np.asarray(tm.vertices), np.asarray(tm.faces)), "zoo")
    surface = np.asarray(trimesh.sample.sample_surface_even(mesh.to_trimesh(), 4000, seed=0)[0])
    return find_aperture(mesh, surface)


def test_a_flat_scissor_ring_hangs_along_its_axis():
    found = _aperture(scissors())
    assert abs(found.axis[2]) > np.cos(np.radians(1.0))  # was 7.6° off before the snap
    assert abs(found.point[1] - -0.018) < 0.003 or abs(found.point[1] - 0.018) < 0.003


def test_an_oblique_ring_keeps_its_own_axis():
    """A ring turned 30° about x: the axis found is the ring's, not the frame's z."""
    ring = trimesh.creation.torus(0.02, 0.004, major_sections=64, minor_sections=16)
    turn = trimesh.transformations.rotation_matrix(np.radians(30), [1, 0, 0])
    ring.apply_transform(turn)
    found = _aperture(ring)
    assert abs(found.axis @ turn[:3, 2]) > np.cos(np.radians(3.0))
