"""Repair of a user's mesh: vertices welded by distance, zero-area faces of a closed
surface kept, and dense meshes simplified to the budget within a measured distance."""

import numpy as np
import pytest
import trimesh
from scipy.spatial import cKDTree

from skt_lib.errors import MeshError
from skt_lib.geometry.convex import Mesh
from skt_lib.geometry.repair import repair, weld
from skt_lib.geometry.simplify import MAX_FACES, hausdorff, simplify_to_budget


def _box() -> trimesh.Trimesh:
    return trimesh.creation.box(extents=(0.04, 0.03, 0.02))


def _with_slivers(tm: trimesh.Trimesh) -> Mesh:
    """``tm`` with two edges out of vertex 0 each split at its midpoint on one side, the
    T-junction closed by a zero-area face (m, a, b): still closed and watertight, with two
    zero-area faces whose boundaries touch at vertex 0."""
    v, f = [np.asarray(x) for x in tm.vertices], [list(x) for x in tm.faces]
    a = 0
    rotated = {k: face[face.index(a):] + face[:face.index(a)] for k, face in enumerate(f)
               if a in face}
    done_b = set()
    for k, (_, b, c) in rotated.items():
        if len(done_b) == 2 or b in done_b:
            continue
        m = len(v)
        v.append((v[a] + v[b]) / 2)
        f[k] = [a, m, c]
        f += [[m, b, c], [m, a, b]]  # the sliver's directed edges close the T-junction
        done_b.add(b)
    return Mesh(np.array(v), np.array(f, dtype=np.int64))


def test_zero_area_faces_of_a_closed_surface_are_kept():
    mesh = _with_slivers(_box())
    tm = mesh.to_trimesh()
    assert tm.is_watertight and tm.is_winding_consistent
    assert (tm.area_faces < 1e-15).sum() >= 1
    out = repair(mesh, "slivers")
    assert out.volume == pytest.approx(0.04 * 0.03 * 0.02, rel=1e-9)


def test_vertices_a_float32_rounding_apart_are_welded():
    tm = _box()
    v, f = tm.vertices[tm.faces].reshape(-1, 3), np.arange(3 * len(tm.faces)).reshape(-1, 3)
    v = v + np.random.default_rng(0).uniform(-3e-9, 3e-9, v.shape)  # an STL's soup, jittered
    welded, faces = weld(v, f)
    assert len(np.unique(faces)) == 8
    assert trimesh.Trimesh(welded, faces, process=False).is_watertight
    assert repair(Mesh(v, f), "soup").volume == pytest.approx(0.04 * 0.03 * 0.02, rel=1e-6)


def test_a_closed_solid_passing_within_the_weld_distance_of_itself_stays_as_it_is():
    """The zoo's slit hook: its surface comes within 15 nm of itself across the slit, ten
    vertex pairs closer than WELD_M. It is closed already, so nothing is welded: the same
    faces and volume come back (a weld by distance pinched the slit's ends into non-manifold
    edges and refused the hook), and a copy of it as an STL's soup closes the same way."""
    from skt_lib.cli.mesh_zoo import slit_hook
    from skt_lib.geometry.repair import WELD_M

    tm = slit_hook()
    closed = trimesh.Trimesh(tm.vertices, tm.faces)  # merged, as trimesh reads an STL
    assert closed.is_watertight and closed.is_winding_consistent and closed.body_count == 1
    assert len(cKDTree(closed.vertices).query_pairs(WELD_M)) >= 6
    out = repair(Mesh(closed.vertices, closed.faces), "slit_hook.stl")
    assert len(out.faces) == len(closed.faces)
    assert out.volume == pytest.approx(closed.volume, rel=1e-9)
    soup = closed.vertices[closed.faces].reshape(-1, 3)
    again = repair(Mesh(soup, np.arange(len(soup)).reshape(-1, 3)), "soup")
    assert len(again.faces) == len(closed.faces)
    assert again.volume == pytest.approx(closed.volume, rel=1e-9)


def test_near_copies_are_welded_only_where_the_surface_is_open():
    """``only``: of two pairs of vertices within the tolerance, the pair with neither vertex
    in ``only`` is left apart, a pair with one in it (an open edge closing onto the closed
    part) is welded."""
    v = np.array([[0, 0, 0], [1e-8, 0, 0], [1, 0, 0], [1 + 1e-8, 0, 0], [0, 1, 0.0]])
    f = np.array([[0, 2, 4], [1, 3, 4]])
    _, faces = weld(v, f, 1e-7, only=np.array([False, False, True, True, False]))
    np.testing.assert_array_equal(faces, [[0, 2, 4], [1, 2, 4]])
    _, faces = weld(v, f, 1e-7, only=np.array([True, False, False, False, False]))
    np.testing.assert_array_equal(faces, [[0, 2, 4], [0, 3, 4]])
    _, faces = weld(v, f, 1e-7)
    np.testing.assert_array_equal(faces, [[0, 2, 4], [0, 2, 4]])


def test_a_large_hole_is_still_refused():
    tm = trimesh.creation.icosphere(4, 0.02)
    keep = tm.vertices[tm.faces][:, :, 2].min(1) < 0.0
    with pytest.raises(MeshError, match="not watertight"):
        repair(Mesh(tm.vertices, tm.faces[keep]), "half sphere")


def test_a_dense_mesh_is_simplified_to_the_budget_within_a_tenth_of_a_millimetre():
    tm = trimesh.creation.torus(0.02, 0.005, major_sections=400, minor_sections=100)
    dense = repair(Mesh(tm.vertices, tm.faces), "torus")
    assert len(dense.faces) == 80_000
    out = simplify_to_budget(dense)
    assert out.faces_before == 80_000 and len(out.mesh.faces) <= MAX_FACES
    assert out.method == "quadric collapse"
    assert 0.0 < out.hausdorff_m <= 1e-4
    assert hausdorff(dense, out.mesh, seed=1) == pytest.approx(out.hausdorff_m, rel=0.5)
    assert out.mesh.volume == pytest.approx(dense.volume, rel=0.01)
    small = simplify_to_budget(out.mesh)
    assert small.method == "none" and small.mesh is out.mesh and small.hausdorff_m == 0.0
