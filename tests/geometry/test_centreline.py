"""Arms and difficulty from a mesh alone (skt_lib.geometry.centreline) against what mesh_gen
measures from the strokes it drew the same shape with."""

import numpy as np
import pytest

from skt_lib.config import LEVELS
from skt_lib.errors import MeshError
from skt_lib.geometry.centreline import find_arms, mesh_difficulty
from skt_lib.geometry.convex import Mesh, union
from skt_lib.geometry.supports import FAMILIES, measure_difficulty

# (family, rise in m): each rise in the middle of its level's band (params level_rise_m)
CASES = [("peg", 0.0), ("angled_peg", 0.0), ("l_hook", 0.012), ("j_hook", 0.03),
         ("j_hook", 0.05), ("double_hook", 0.012), ("rack", 0.0), ("rack", 0.012)]


@pytest.mark.parametrize("family, rise", CASES)
def test_mesh_only_difficulty_matches_the_strokes(tiny_params, family, rise):
    p = tiny_params.mesh_gen
    rng = np.random.default_rng(3)
    shape = FAMILIES[family](rng, 0.004, False, rise, p)
    want = measure_difficulty(shape, p)
    got, arm, arms = mesh_difficulty(union(shape.parts()), p)
    assert got.level == want.level, (got, want)
    assert abs(got.blocking_height_m - want.blocking_height_m) <= 0.004
    assert np.linalg.norm(np.subtract(got.hang_point, want.hang_point)) <= 0.008
    assert arm.radius == pytest.approx(0.004, abs=0.0008)
    if family == "double_hook":
        assert len(arms) == 2 and got.hang_point[2] < 0.02  # the lower hook, not the upper peg
    if family == "rack":
        assert len(arms) >= 3 and abs(got.hang_point[1]) < 0.005  # the middle prong


def test_levels_follow_the_blocking_height(tiny_params):
    p = tiny_params.mesh_gen
    got = [mesh_difficulty(union(FAMILIES["j_hook"](np.random.default_rng(5), 0.004, False, rise,
                                                    p).parts()), p)[0].level
           for rise in (0.003, 0.012, 0.03, 0.05)]
    assert got == list(LEVELS)


def test_a_mesh_off_the_wall_has_no_arm(tiny_params):
    shape = FAMILIES["peg"](np.random.default_rng(0), 0.004, False, 0.0, tiny_params.mesh_gen)
    mesh = union(shape.parts())
    moved = Mesh(mesh.vertices + [0.05, 0.0, 0.0], mesh.faces)
    with pytest.raises(MeshError, match="touches the wall"):
        find_arms(moved)
