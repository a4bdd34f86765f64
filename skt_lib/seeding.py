"""Per-item random generators derived from one seed.

Every item gets its own :class:`numpy.random.Generator` from ``(seed, stage, item key)``,
so results do not depend on processing order, worker count or backend.
"""

import hashlib

import numpy as np


def _key_words(key: str) -> list[int]:
    digest = hashlib.blake2b(key.encode("utf-8"), digest_size=16).digest()
    return [int.from_bytes(digest[i : i + 4], "little") for i in range(0, 16, 4)]


def item_rng(seed: int, stage: str, item: str | int) -> np.random.Generator:
    """Generator for one item of one stage; stable across Python runs and platforms."""
    if not isinstance(seed, int) or seed < 0:
        raise ValueError(f"seed must be a non-negative int, got {seed!r}")
    words = _key_words(f"{stage}/{item}")
    return np.random.Generator(np.random.PCG64(np.random.SeedSequence([seed, *words])))
