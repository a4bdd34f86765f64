import numpy as np
import pytest

from skt_lib.errors import MeshError
from skt_lib.geometry.checks import check_parts, check_solid, convexity_gap
from skt_lib.geometry.convex import (
    Mesh, box, capsule, hull, intersection_volume, square_segment, tube, union,
)


def test_hull_is_outward_convex_and_exact_for_a_box():
    rng = np.random.default_rng(0)
    pts = rng.normal(size=(200, 3)) * 0.02
    h = hull(pts)
    check_solid(h, "hull")
    assert convexity_gap(h) < 1e-9
    b = box([0.1, 0, 0], [0.01, 0.02, 0.03])
    assert b.volume == pytest.approx(0.02 * 0.04 * 0.06, rel=1e-12)


def test_capsule_volume_close_to_analytic():
    r, length = 0.005, 0.05
    c = capsule([0, 0, 0], [length, 0, 0], r, subdivisions=3)
    exact = np.pi * r**2 * length + 4 / 3 * np.pi * r**3
    assert c.volume == pytest.approx(exact, rel=0.02)
    assert c.volume < exact  # inscribed polytope


def test_square_segments_cover_a_right_angle_joint():
    pts = np.array([[0, 0, 0], [0.05, 0, 0], [0.05, 0, 0.05]], float)
    parts = tube(pts, 0.004, square=True)
    u = union(parts)
    check_solid(u, "L")
    # the outer corner of the bend is covered: a probe cube at the corner lies inside
    probe = box([0.0535, 0.0, -0.0035], [0.0004] * 3)
    assert intersection_volume([probe], u) == pytest.approx(probe.volume, rel=1e-9)
    with pytest.raises(ValueError, match="coincide"):
        square_segment([0, 0, 0], [0, 0, 0], 0.01, np.array([0, 1.0, 0]))


def test_check_solid_rejects_open_inverted_and_millimetre_meshes():
    b = box([0, 0, 0], [0.01, 0.01, 0.01])
    with pytest.raises(MeshError, match="not watertight"):
        check_solid(Mesh(b.vertices, b.faces[:-1]), "open")
    with pytest.raises(MeshError, match="non-positive volume"):
        check_solid(Mesh(b.vertices, b.faces[:, ::-1].copy()), "inverted")
    with pytest.raises(MeshError, match="millimetres"):
        check_solid(Mesh(b.vertices * 1000, b.faces), "mm")
    with pytest.raises(MeshError, match="non-finite"):
        check_solid(Mesh(b.vertices * np.nan, b.faces), "nan")


def test_check_parts_rejects_non_convex_part_and_poor_coverage():
    a = box([0, 0, 0], [0.01, 0.01, 0.01])
    b = box([0.015, 0, 0], [0.01, 0.01, 0.01])
    u = union([a, b])
    assert check_parts([a, b], u, "ok") == pytest.approx(1.0, abs=1e-9)
    with pytest.raises(MeshError, match="IoU"):
        check_parts([a], u, "half")
    l_shape = union([box([0, 0, 0], [0.02, 0.01, 0.005]), box([0.015, 0, 0.015], [0.005, 0.01, 0.02])])
    with pytest.raises(MeshError, match="not convex"):
        check_parts([l_shape], l_shape, "concave")
