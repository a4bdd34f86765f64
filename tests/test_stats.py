"""Wilson intervals and the exact paired (McNemar) test against hand-computed values; the
cluster bootstrap over supports."""

import numpy as np
import pytest

from skt_lib.stats import (
    A_BETTER, B_BETTER, NO_DIFFERENCE, bootstrap_mean_interval, mcnemar_exact_p,
    paired_comparison, paired_comparisons, paired_support_interval, success_ci95, support_ci95,
    wilson_interval,
)

Z2 = 1.959963984540054 ** 2  # z_{0.975}^2


def test_wilson_hand_computed_values():
    # k = 0: [0, z²/(n + z²)]; k = n: the mirror image
    assert wilson_interval(0, 10) == (0.0, pytest.approx(Z2 / (10 + Z2)))
    assert wilson_interval(0, 10)[1] == pytest.approx(0.2775, abs=5e-5)
    assert wilson_interval(10, 10) == (pytest.approx(10 / (10 + Z2)), 1.0)
    assert wilson_interval(10, 10)[0] == pytest.approx(0.7225, abs=5e-5)
    # 5/10: 0.5 ± z·sqrt(0.025 + z²/400) / (1 + z²/10) = [0.2366, 0.7634] (published tables)
    lo, hi = wilson_interval(5, 10)
    assert lo == pytest.approx(0.23659, abs=5e-5) and hi == pytest.approx(0.76341, abs=5e-5)
    # 1/20 (Newcombe 1998, table I: 0.0089–0.2361)
    lo, hi = wilson_interval(1, 20)
    assert lo == pytest.approx(0.0089, abs=5e-5) and hi == pytest.approx(0.2361, abs=5e-5)
    # a 99 % interval is wider than the 95 % one
    lo99, hi99 = wilson_interval(5, 10, confidence=0.99)
    assert lo99 < 0.2366 and hi99 > 0.7634


def test_wilson_edge_cases_and_input_checks():
    assert wilson_interval(0, 0) is None
    for k, n in [(3, 7), (1, 1), (0, 1), (99, 100)]:
        lo, hi = wilson_interval(k, n)
        assert 0.0 <= lo < k / n or k == 0
        assert k / n < hi <= 1.0 or k == n
    with pytest.raises(ValueError, match="k"):
        wilson_interval(11, 10)
    with pytest.raises(ValueError, match="n"):
        wilson_interval(0, -1)
    with pytest.raises(ValueError, match="k"):
        wilson_interval(1.5, 3)
    with pytest.raises(ValueError, match="confidence"):
        wilson_interval(1, 3, confidence=1.0)


@pytest.mark.parametrize("b,c,p", [
    (1, 9, 22 / 1024),           # 2·(C(10,0) + C(10,1)) / 2^10
    (2, 8, 112 / 1024),          # 2·(1 + 10 + 45) / 2^10
    (0, 5, 2 / 32),              # 5–0 is not significant at 0.05
    (0, 6, 2 / 64),              # 6–0 is
    (4, 4, 1.0),
    (0, 0, 1.0),
    (7, 3, 2 * (1 + 10 + 45 + 120) / 1024),
])
def test_mcnemar_exact_p_hand_computed(b, c, p):
    assert mcnemar_exact_p(b, c) == pytest.approx(p, rel=1e-9)
    assert mcnemar_exact_p(c, b) == pytest.approx(p, rel=1e-9)  # two-sided: symmetric


def test_paired_comparison_counts_and_verdicts():
    # 3 both, 1 A only, 9 B only, 2 neither → p = 22/1024, B better
    a = np.array([1, 1, 1, 1] + [0] * 9 + [0, 0], bool)
    b = np.array([1, 1, 1, 0] + [1] * 9 + [0, 0], bool)
    r = paired_comparison(a, b)
    assert (r.n_pairs, r.n_both, r.n_a_only, r.n_b_only) == (15, 3, 1, 9)
    assert r.p_value == pytest.approx(22 / 1024) and r.verdict == B_BETTER
    assert paired_comparison(b, a).verdict == A_BETTER
    assert paired_comparison(b, a).as_dict() == {"n_pairs": 15, "n_both": 3, "n_a_only": 9,
                                                 "n_b_only": 1, "p_value": pytest.approx(22 / 1024),
                                                 "verdict": A_BETTER}
    # 5–0 discordant: a big raw gap (rates 5/5 vs 0/5) yet not significant
    r = paired_comparison([1] * 5, [0] * 5)
    assert r.n_a_only == 5 and r.p_value == pytest.approx(0.0625) and r.verdict == NO_DIFFERENCE
    assert paired_comparison([1] * 6, [0] * 6).verdict == A_BETTER
    # the threshold is strict: p must be below alpha
    assert paired_comparison([1] * 6, [0] * 6, alpha=2 / 64).verdict == NO_DIFFERENCE
    with pytest.raises(ValueError, match="same trials"):
        paired_comparison([1, 0], [1])
    with pytest.raises(ValueError, match="boolean"):
        paired_comparison([2, 0], [1, 0])


def _trials():
    import pandas as pd

    rows = []
    # sctdn wins 6 discordant pairs against kpam, ties template_only; trial order differs
    for i in range(8):
        for m, ok in (("sctdn", i < 7), ("kpam", i == 0), ("template_only", i < 7)):
            rows.append({"method": m, "support_id": f"s{i % 4}", "object_id": f"o{i // 4}",
                         "difficulty": "easy" if i % 4 < 2 else "hard", "success": ok})
    return pd.DataFrame(rows[::-1])


def test_success_ci95_per_method_and_level():
    ci = success_ci95(_trials(), ("easy", "normal", "hard"))
    assert set(ci) == {"sctdn", "kpam", "template_only"}
    assert ci["sctdn"]["all"] == pytest.approx(list(wilson_interval(7, 8)))
    assert ci["kpam"]["easy"] == pytest.approx(list(wilson_interval(1, 4)))
    assert ci["kpam"]["hard"] == [0.0, pytest.approx(Z2 / (4 + Z2))]
    assert ci["sctdn"]["normal"] is None


def test_paired_comparisons_match_trials_by_support_and_object():
    t = _trials()
    out = paired_comparisons(t, "sctdn")
    assert set(out) == {"sctdn_vs_kpam", "sctdn_vs_template_only"}
    k = out["sctdn_vs_kpam"]
    assert (k["n_pairs"], k["n_both"], k["n_a_only"], k["n_b_only"]) == (8, 1, 6, 0)
    assert k["p_value"] == pytest.approx(2 / 64) and k["verdict"] == A_BETTER
    same = out["sctdn_vs_template_only"]
    assert (same["n_a_only"], same["n_b_only"], same["verdict"]) == (0, 0, NO_DIFFERENCE)
    # only trials both methods ran are paired
    out = paired_comparisons(t[~((t["method"] == "kpam") & (t["support_id"] == "s1"))], "sctdn")
    assert out["sctdn_vs_kpam"]["n_pairs"] == 6
    assert paired_comparisons(t[t["method"] != "sctdn"], "sctdn") == {}
    with pytest.raises(ValueError, match="several trials"):
        paired_comparisons(pd_concat(t, t[:1]), "sctdn")


def pd_concat(a, b):
    import pandas as pd

    return pd.concat([a, b], ignore_index=True)


def test_bootstrap_resamples_whole_supports():
    """Five identical views per support carry no more information than one: the cluster
    bootstrap gives the same interval for both (an item bootstrap would narrow by ~√5)."""
    per_support = np.random.default_rng(0).normal(10.0, 3.0, 40)
    one = bootstrap_mean_interval(per_support, np.arange(40), np.random.default_rng(1))
    five = bootstrap_mean_interval(np.repeat(per_support, 5), np.repeat(np.arange(40), 5),
                                   np.random.default_rng(1))
    assert one == pytest.approx(five, abs=1e-12)
    lo, hi = one
    se = per_support.std(ddof=1) / np.sqrt(40)
    assert lo < per_support.mean() < hi
    assert hi - lo == pytest.approx(2 * 1.96 * se, rel=0.15)


def test_bootstrap_weights_supports_by_their_views_and_checks_input():
    # a constant gives a point interval; unequal view counts weigh each item, not each support
    assert bootstrap_mean_interval([2.0, 2.0, 2.0], ["a", "a", "b"],
                                   np.random.default_rng(0)) == (2.0, 2.0)
    lo, hi = bootstrap_mean_interval([0.0, 0.0, 0.0, 3.0], ["a", "a", "a", "b"],
                                     np.random.default_rng(0), n_boot=4000)
    assert (lo, hi) == (0.0, 3.0)  # resamples: aa -> 0, bb -> 3, ab -> 0.75
    assert bootstrap_mean_interval([], [], np.random.default_rng(0)) is None
    with pytest.raises(ValueError, match="values, groups"):
        bootstrap_mean_interval([1.0, 2.0], ["a"], np.random.default_rng(0))
    with pytest.raises(ValueError, match="finite"):
        bootstrap_mean_interval([1.0, np.nan], ["a", "b"], np.random.default_rng(0))


def test_support_ci95_draws_supports_not_pairs():
    """Two methods at 50 %: one whose supports hang all or nothing (10 objects each), one
    whose every support hangs half. The first's support interval is wide (4 supports decide
    it), the second's has no spread at all; Wilson gives both the same interval."""
    import pandas as pd

    rows = []
    for si in range(4):
        for oi in range(10):
            rows.append({"method": "lumpy", "support_id": f"s{si}", "difficulty": "easy",
                         "success": si % 2 == 0})
            rows.append({"method": "even", "support_id": f"s{si}", "difficulty": "easy",
                         "success": oi % 2 == 0})
    pairs = pd.DataFrame(rows)
    got = support_ci95(pairs, ("easy", "hard"), np.random.default_rng(0))
    assert got["even"]["all"] == pytest.approx([0.5, 0.5])
    lo, hi = got["lumpy"]["all"]
    assert lo <= 0.25 and hi >= 0.75  # 4 all-or-nothing supports: 0, 1/4, … 1 of them drawn
    assert got["lumpy"]["easy"] == got["lumpy"]["all"] and got["lumpy"]["hard"] is None
    assert success_ci95(pairs, ("easy",))["lumpy"] == success_ci95(pairs, ("easy",))["even"]


def test_paired_support_interval_is_of_the_difference_on_the_same_pairs():
    a = np.array([1, 1, 1, 1, 0, 0, 1, 1], bool)
    b = np.array([0, 0, 1, 1, 0, 0, 0, 0], bool)
    groups = np.array(["s0", "s0", "s1", "s1", "s2", "s2", "s3", "s3"])
    lo, hi = paired_support_interval(a, b, groups, np.random.default_rng(1))
    # per-support differences 1, 0, 0, 1: the mean 0.5, every resample in [0, 1]
    assert 0.0 <= lo < 0.5 < hi <= 1.0
    assert paired_support_interval(a, a, groups, np.random.default_rng(1)) == (0.0, 0.0)
    with pytest.raises(ValueError, match="same pairs"):
        paired_support_interval(a, b[:-1], groups, np.random.default_rng(1))
