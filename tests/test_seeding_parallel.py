import numpy as np
import pytest

from skt_lib.config import ComputeParams
from skt_lib.errors import GenerationFailed
from skt_lib.parallel import Failed, capture, map_items
from skt_lib.seeding import item_rng


def test_item_rng_depends_only_on_seed_stage_item():
    a = item_rng(3, "stage", "support_00001").random(4)
    assert np.array_equal(a, item_rng(3, "stage", "support_00001").random(4))
    assert not np.array_equal(a, item_rng(3, "stage", "support_00002").random(4))
    assert not np.array_equal(a, item_rng(4, "stage", "support_00001").random(4))
    assert not np.array_equal(a, item_rng(3, "other", "support_00001").random(4))
    with pytest.raises(ValueError, match="seed"):
        item_rng(-1, "s", 0)


def draw(i):  # top-level: pickled to workers
    return float(item_rng(11, "test", i).normal())


def fail_odd(i):
    if i % 2:
        raise GenerationFailed(f"item {i}", "odd")
    return i


def test_local_backend_same_result_for_any_worker_count():
    items = list(range(12))
    one = map_items(draw, items, ComputeParams(backend="local", n_workers=1))
    two = map_items(draw, items, ComputeParams(backend="local", n_workers=2))
    assert one == two == [draw(i) for i in items]


@pytest.mark.slow
def test_dask_backend_matches_local():
    items = list(range(6))
    done = []
    got = map_items(draw, items, ComputeParams(backend="dask", n_workers=2), on_done=lambda i, r: done.append((i, r)))
    assert got == [draw(i) for i in items]
    assert sorted(done) == [(i, draw(i)) for i in items]


def test_capture_turns_expected_failures_into_values_only():
    out = [capture(fail_odd, i) for i in range(3)]
    assert out[0] == 0 and out[2] == 2
    assert isinstance(out[1], Failed) and out[1].reason == "odd"
    with pytest.raises(ZeroDivisionError):
        capture(lambda _: 1 / 0, 0)
