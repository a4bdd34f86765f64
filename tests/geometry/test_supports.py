import numpy as np
import pytest

from skt_lib.config import LEVELS
from skt_lib.geometry.checks import check_parts, check_solid
from skt_lib.geometry.convex import union
from skt_lib.geometry.supports import (
    FAMILIES, LEVEL_FAMILIES, SupportShape, Stroke, _Path, measure_difficulty, sample_support,
)
from skt_lib.seeding import item_rng


@pytest.mark.parametrize("level", LEVELS)
def test_sampled_supports_have_the_target_level_and_valid_geometry(level, tiny_params):
    p = tiny_params.mesh_gen
    for k in range(6):
        shape, diff = sample_support(item_rng(1, "t", f"{level}{k}"), level, p)
        assert diff.level == level == measure_difficulty(shape, p).level
        assert shape.family in LEVEL_FAMILIES[level]
        parts = shape.parts()
        visual = union(parts)
        check_solid(visual, shape.family)
        assert check_parts(parts, visual, shape.family) >= 0.95
        hang = np.asarray(diff.hang_point)
        assert hang[0] >= 0.025 - 1e-9  # hang point off the wall
        # support frame: wall plate behind x = 0 never, everything in front of the wall
        assert visual.vertices[:, 0].min() >= -1e-9


def _arm(path, r=0.004, square=False):
    return Stroke(path.array(), r, square)


def test_straight_peg_has_no_blocking_and_is_easy(tiny_params):
    shape = SupportShape("peg", (_arm(_Path((0.005, 0, 0), 10).straight(0.1)),))
    d = measure_difficulty(shape, tiny_params.mesh_gen)
    assert d.blocking_height_m == pytest.approx(0.0, abs=1e-9)
    assert d.clearance_above_m == 1.0 and d.level == "easy"


def test_l_hook_blocking_height_is_its_tip_height(tiny_params):
    # horizontal arm, sharp 90° bend of radius 6 mm, 24 mm straight tip: rise = 30 mm
    path = _Path((0.005, 0, 0), 0).straight(0.08).arc(0.006, 90).straight(0.024)
    d = measure_difficulty(SupportShape("l_hook", (_arm(path),)), tiny_params.mesh_gen)
    assert d.blocking_height_m == pytest.approx(0.030, abs=2e-4)
    assert d.level == "hard"  # 20 mm <= 30 mm < 40 mm
    assert d.tip_turn_deg == pytest.approx(90, abs=1)


def test_curl_is_very_hard_whatever_its_height(tiny_params):
    path = _Path((0.005, 0, 0), -2).straight(0.07).arc(0.006, 230)
    d = measure_difficulty(SupportShape("curled_hook", (_arm(path),)), tiny_params.mesh_gen)
    assert d.blocking_height_m < 0.02 and d.tip_turn_deg > 200 and d.level == "very_hard"


def test_prong_above_the_arm_makes_a_narrow_gap_one_level_harder(tiny_params):
    p = tiny_params.mesh_gen
    arm = _arm(_Path((0.005, 0, 0), 5).straight(0.09))
    for dz, expect in [(0.03, "normal"), (0.2, "easy")]:
        upper = _arm(_Path((0.005, 0, dz), 0).straight(0.09))
        d = measure_difficulty(SupportShape("double_hook", (arm, upper)), p)
        assert d.level == expect, (dz, d)
    assert d.clearance_above_m == 1.0 or d.clearance_above_m > p.narrow_gap_m


def test_every_family_builds(tiny_params):
    rng = np.random.default_rng(5)
    for name, fn in FAMILIES.items():
        shape = fn(rng, 0.004, name == "rack", 0.01, tiny_params.mesh_gen)
        check_solid(union(shape.parts()), name)
