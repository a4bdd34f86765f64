"""Train/val/test split by supporting item, balanced per difficulty level in val and test."""

from skt_lib.config import LEVELS
from skt_lib.errors import GenerationFailed
from skt_lib.seeding import item_rng


def assign_splits(ids: list[str], levels: list[str], seed: int, n_val: int, n_test: int,
                  groups: tuple[str, ...] = LEVELS, key: str = "mesh_gen/split") -> list[str]:
    """Split label per id: exactly ``n_test`` test and ``n_val`` val ids per group (difficulty
    level by default), chosen by a seeded permutation of that group's ids sorted by id
    (order-independent)."""
    if len(ids) != len(levels):
        raise ValueError("ids and levels differ in length")
    split = {}
    for level in groups:
        members = sorted(i for i, lv in zip(ids, levels) if lv == level)
        if len(members) < n_val + n_test + 1:
            raise GenerationFailed(
                f"{level!r} has {len(members)} items; needs {n_val + n_test + 1} "
                "(val + test + at least one train)", "split_too_small"
            )
        order = item_rng(seed, key, level).permutation(len(members))
        for rank, j in enumerate(order):
            split[members[j]] = "test" if rank < n_test else "val" if rank < n_test + n_val else "train"
    return [split[i] for i in ids]
