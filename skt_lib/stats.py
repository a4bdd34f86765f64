"""Error bars: Wilson intervals for rates, exact paired (McNemar) comparisons, and a cluster
bootstrap for means over items grouped by support.

Trials are Bernoulli outcomes. A rate gets a Wilson score interval (better than the normal
approximation at the extremes and at small ``n``, where Table I lives). Two methods run on
the same trials are compared on the discordant pairs only (exact two-sided McNemar test:
a binomial test of ``n_a_only`` against ``Binomial(n_a_only + n_b_only, 1/2)``).
"""

import math
from dataclasses import dataclass

import numpy as np
from scipy.stats import binomtest, norm

#: Verdicts of :func:`paired_comparison`.
A_BETTER, B_BETTER, NO_DIFFERENCE = "A better", "B better", "no significant difference"


def wilson_interval(k: int, n: int, confidence: float = 0.95) -> tuple[float, float] | None:
    """Wilson score interval ``(lo, hi)`` (fractions in [0, 1]) for ``k`` successes in ``n``
    trials; ``None`` when ``n == 0`` (no trials, no rate)."""
    k, n = _count(k, "k"), _count(n, "n")
    if k > n:
        raise ValueError(f"k: {k} successes exceed n = {n} trials")
    if not 0.0 < confidence < 1.0:
        raise ValueError(f"confidence: must be in (0, 1), got {confidence}")
    if n == 0:
        return None
    z = float(norm.ppf(0.5 + confidence / 2))
    p = k / n
    denom = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    # exact endpoints at k = 0 and k = n (the formula gives them up to rounding)
    lo = 0.0 if k == 0 else max(0.0, centre - half)
    hi = 1.0 if k == n else min(1.0, centre + half)
    return lo, hi


def bootstrap_mean_interval(values, groups, rng: np.random.Generator, n_boot: int = 2000,
                            confidence: float = 0.95) -> tuple[float, float] | None:
    """Percentile interval ``(lo, hi)`` of the mean of ``values (n,)`` under a cluster bootstrap:
    each resample draws whole groups (e.g. supports, whose views are not independent) with
    replacement and averages every value of the drawn groups. ``None`` when there are no values."""
    values, groups = np.asarray(values, np.float64), np.asarray(groups)
    if values.ndim != 1 or groups.shape != values.shape:
        raise ValueError(f"values, groups: need two 1-D arrays of one length, got shapes "
                         f"{values.shape} and {groups.shape}")
    if not np.isfinite(values).all():
        raise ValueError("values: must be finite")
    if n_boot < 1 or not 0.0 < confidence < 1.0:
        raise ValueError(f"n_boot >= 1 and confidence in (0, 1) needed, got {n_boot}, {confidence}")
    if len(values) == 0:
        return None
    _, inverse = np.unique(groups, return_inverse=True)
    sums, counts = np.bincount(inverse, values), np.bincount(inverse)
    draws = rng.integers(0, len(sums), size=(n_boot, len(sums)))
    means = sums[draws].sum(1) / counts[draws].sum(1)
    tail = 50 * (1 - confidence)
    lo, hi = np.percentile(means, [tail, 100 - tail])
    return float(lo), float(hi)


@dataclass(frozen=True)
class PairedComparison:
    """Method A vs method B on the same trials."""

    n_pairs: int  # trials both methods ran
    n_both: int  # both succeeded
    n_a_only: int  # A succeeded, B failed
    n_b_only: int  # B succeeded, A failed
    p_value: float  # exact two-sided McNemar (binomial test on the discordant pairs)
    verdict: str  # "A better", "B better" or "no significant difference" at ``alpha``

    def as_dict(self) -> dict:
        return {"n_pairs": self.n_pairs, "n_both": self.n_both, "n_a_only": self.n_a_only,
                "n_b_only": self.n_b_only, "p_value": self.p_value, "verdict": self.verdict}


def mcnemar_exact_p(n_a_only: int, n_b_only: int) -> float:
    """Exact two-sided McNemar p-value for the discordant counts (1.0 when there are none)."""
    b, c = _count(n_a_only, "n_a_only"), _count(n_b_only, "n_b_only")
    if b + c == 0:
        return 1.0
    return float(binomtest(b, b + c, 0.5, alternative="two-sided").pvalue)


def paired_comparison(a, b, alpha: float = 0.05) -> PairedComparison:
    """Compare success flags ``a (n,)`` and ``b (n,)`` of two methods on the same ``n``
    trials (element ``i`` of both is the same trial). "A better" only when A wins more
    discordant pairs and the exact McNemar p-value is below ``alpha``."""
    a, b = _flags(a, "a"), _flags(b, "b")
    if a.shape != b.shape:
        raise ValueError(f"a, b: need the same trials, got {a.shape} and {b.shape}")
    if not 0.0 < alpha < 1.0:
        raise ValueError(f"alpha: must be in (0, 1), got {alpha}")
    n_a_only, n_b_only = int((a & ~b).sum()), int((b & ~a).sum())
    p = mcnemar_exact_p(n_a_only, n_b_only)
    verdict = NO_DIFFERENCE
    if p < alpha:
        verdict = A_BETTER if n_a_only > n_b_only else B_BETTER
    return PairedComparison(len(a), int((a & b).sum()), n_a_only, n_b_only, p, verdict)


def _count(x, name: str) -> int:
    if isinstance(x, bool) or int(x) != x or x < 0:
        raise ValueError(f"{name}: expected a non-negative integer, got {x!r}")
    return int(x)


def _flags(x, name: str) -> np.ndarray:
    arr = np.asarray(x)
    if arr.ndim != 1:
        raise ValueError(f"{name}: expected a 1-D array of success flags, got shape {arr.shape}")
    if arr.dtype != bool:
        if not np.isin(arr, (0, 1)).all():
            raise ValueError(f"{name}: success flags must be boolean (or 0/1)")
        arr = arr.astype(bool)
    return arr


def success_ci95(trials, levels) -> dict:
    """``{method: {"all": [lo, hi], <level>: [lo, hi] | None, …}}``: Wilson 95 % intervals
    of the success rate per method, over all trials and per difficulty level, from a trials
    table with columns ``method``, ``difficulty``, ``success`` (``None`` where no trials)."""
    out = {}
    for method, g in trials.groupby("method", sort=False):
        out[method] = {"all": _ci(g["success"])}
        for level in levels:
            out[method][level] = _ci(g.loc[g["difficulty"] == level, "success"])
    return out


def paired_comparisons(trials, reference: str, alpha: float = 0.05) -> dict:
    """``{"<reference>_vs_<other>": PairedComparison.as_dict()}`` for every other method in
    the trials table (columns ``method``, ``support_id``, ``object_id``, ``success``), on the
    trials both ran, matched by ``(support_id, object_id)``; A is ``reference``. Empty when
    ``reference`` did not run."""
    key = ["support_id", "object_id"]
    methods = list(dict.fromkeys(trials["method"]))
    if reference not in methods:
        return {}
    flags = {}
    for m in methods:
        g = trials[trials["method"] == m]
        if g.duplicated(key).any():
            raise ValueError(f"trials: method {m!r} has several trials for one (support, object)")
        flags[m] = g.set_index(key)["success"].astype(bool)
    out = {}
    for other in methods:
        if other == reference:
            continue
        a, b = flags[reference].align(flags[other], join="inner")
        out[f"{reference}_vs_{other}"] = paired_comparison(a.to_numpy(), b.to_numpy(),
                                                           alpha).as_dict()
    return out


def support_ci95(pairs, levels, rng: np.random.Generator, n_boot: int = 2000) -> dict:
    """``{method: {"all": [lo, hi], <level>: [lo, hi] | None, …}}``: 95 % intervals of the
    success rate per method from a bootstrap over test supports (a support's pairs drawn
    together: its objects mostly hang or fail together, so the support is the unit of
    evidence), over all pairs and per level; columns ``method``, ``support_id``,
    ``difficulty``, ``success``. ``None`` where a level has no pairs."""
    out = {}
    for method, g in pairs.groupby("method", sort=False):
        out[method] = {}
        for level in ("all", *levels):
            sub = g if level == "all" else g[g["difficulty"] == level]
            ci = bootstrap_mean_interval(sub["success"].to_numpy(float), sub["support_id"].to_numpy(),
                                         rng, n_boot)
            out[method][level] = None if ci is None else [ci[0], ci[1]]
    return out


def paired_support_interval(a, b, groups, rng: np.random.Generator, n_boot: int = 2000
                            ) -> tuple[float, float] | None:
    """95 % interval of the mean difference ``a − b`` (success flags of two methods on the
    same pairs, element ``i`` the same pair) under a bootstrap over ``groups`` (the pairs'
    supports, drawn with all their pairs)."""
    a, b = _flags(a, "a"), _flags(b, "b")
    if a.shape != b.shape:
        raise ValueError(f"a, b: need the same pairs, got {a.shape} and {b.shape}")
    return bootstrap_mean_interval(a.astype(float) - b.astype(float), groups, rng, n_boot)


def _ci(success) -> list[float] | None:
    ci = wilson_interval(int(np.asarray(success, bool).sum()), len(success))
    return None if ci is None else [ci[0], ci[1]]
