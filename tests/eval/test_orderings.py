"""The paper's orderings and oracle-conditioned rates, on hand-made pair tables."""

import pandas as pd
import pytest

from skt_lib.eval.orderings import check_orderings, explain, success_given


def _pairs(flags: dict[str, list[bool]], levels: list[str]) -> pd.DataFrame:
    rows = []
    for method, ok in flags.items():
        for i, (s, lv) in enumerate(zip(ok, levels)):
            rows.append({"method": method, "support_id": f"s{i}", "object_id": "o",
                         "difficulty": lv, "success": s})
    return pd.DataFrame(rows)


def test_orderings_use_the_same_pairs_the_margin_and_the_level():
    lv = ["easy"] * 6 + ["very_hard"] * 4
    pairs = _pairs({"sctdn": [1, 1, 1, 1, 1, 0, 1, 1, 0, 0],
                    "vatmart_mod": [1, 1, 1, 0, 0, 0, 1, 1, 1, 0],
                    "vatmart": [1, 1, 0, 0, 0, 0, 0, 0, 0, 0],
                    "template_only": [1, 1, 1, 1, 0, 0, 1, 1, 0, 0]}, lv)
    got = {c["claim"]: c for c in check_orderings(pairs)}
    c = got["sctdn > vatmart_mod (all levels)"]
    assert (c["rate_a"], c["rate_b"], c["holds"]) == (0.7, 0.6, True)
    assert (c["n_pairs"], c["n_a_only"], c["n_b_only"]) == (10, 2, 1)
    assert c["p_value"] == pytest.approx(1.0)  # 2 vs 1 discordant: no evidence
    # +10 points exactly: 0.7 vs 0.6 holds (≥), a point less would not
    assert got["sctdn ≥ template_only + 10 points (all levels)"]["holds"]
    vh = got["Very Hard: sctdn ≥ vatmart_mod"]
    assert (vh["n_pairs"], vh["rate_a"], vh["rate_b"], vh["holds"]) == (4, 0.5, 0.75, False)
    assert got["vatmart_mod > vatmart (all levels)"]["holds"]
    # a method that did not run: its orderings are left out, not reported as failing
    assert [c["claim"] for c in check_orderings(pairs[pairs["method"] != "vatmart"])] == [
        "sctdn > vatmart_mod (all levels)", "sctdn ≥ template_only + 10 points (all levels)",
        "Very Hard: sctdn ≥ vatmart_mod"]


def test_equal_rates_fail_a_strict_ordering_and_pass_a_non_strict_one():
    pairs = _pairs({"sctdn": [1, 0, 0], "vatmart_mod": [0, 1, 0]}, ["very_hard"] * 3)
    got = {c["claim"]: c for c in check_orderings(pairs)}
    pooled, vh = got["sctdn > vatmart_mod (all levels)"], got["Very Hard: sctdn ≥ vatmart_mod"]
    assert pooled["rate_a"] == pooled["rate_b"] and not pooled["holds"]
    assert vh["rate_a"] == vh["rate_b"] and vh["holds"]


def test_within_restricts_to_the_given_pairs_and_explain_names_the_evidence():
    lv = ["easy"] * 4
    pairs = _pairs({"sctdn": [1, 0, 0, 0], "vatmart_mod": [1, 1, 1, 0],
                    "oracle": [1, 1, 0, 0]}, lv)
    oracle = pairs[pairs["method"] == "oracle"].set_index(["support_id", "object_id"])["success"]
    (c,) = [c for c in check_orderings(pairs) if c["claim"].startswith("sctdn >")]
    (h,) = [c for c in check_orderings(pairs, within=oracle.astype(bool))
            if c["claim"].startswith("sctdn >")]
    assert (c["n_pairs"], c["rate_b"]) == (4, 0.75) and (h["n_pairs"], h["rate_b"]) == (2, 1.0)
    text = explain(c, 0.5, h)
    assert "25.0 % vs 75.0 %" in text and "no significant difference" in text
    assert "on the 2 pairs the oracle hangs: 50.0 % vs 100.0 %" in text
    assert explain({**c, "holds": True}, 0.5, h) == ""
    zero = {**c, "rate_a": 0.0, "rate_b": 0.0}
    assert "nothing to rank" in explain(zero, 0.0, None)
    assert "nothing to rank" not in explain(zero, 0.18, None)
    assert explain({**zero, "holds": True}, 0.0, None).startswith(
        f"{c['claim']}: holds only because neither hangs")


def test_success_given_the_oracle_splits_on_its_verdict():
    pairs = _pairs({"oracle": [1, 1, 1, 0, 0], "sctdn": [1, 0, 1, 1, 0]}, ["easy"] * 5)
    got = success_given(pairs, "oracle")
    assert got["sctdn"] == {"n_ref_ok": 3, "on_ref_ok": pytest.approx(2 / 3),
                            "n_ref_failed": 2, "on_ref_failed": 0.5}
    assert got["oracle"]["on_ref_ok"] == 1.0 and got["oracle"]["on_ref_failed"] == 0.0
    assert success_given(pairs[pairs["method"] != "oracle"], "oracle") == {}


def _support_pairs(a_by_support, b_by_support, n_objects=10) -> pd.DataFrame:
    """Each support's objects hang or fail together for both methods."""
    rows = []
    for si, (a, b) in enumerate(zip(a_by_support, b_by_support)):
        for oi in range(n_objects):
            for method, ok in (("sctdn", a), ("vatmart_mod", b)):
                rows.append({"method": method, "support_id": f"s{si}", "object_id": f"o{oi}",
                             "difficulty": "easy", "success": bool(ok)})
    return pd.DataFrame(rows)


def test_the_support_bootstrap_judges_an_ordering_that_mcnemar_calls_certain():
    """sctdn hangs 3 supports vatmart_mod does not and loses 1 (of 20 supports, 10 objects
    each): McNemar on the 200 pairs calls it (30 vs 10 discordant pairs), but four supports
    decide it, so on supports the claim is undecided; 12 supports won and none lost shows it;
    the mirror image is reversed."""
    a = [1] * 3 + [0] + [1] * 8 + [0] * 8
    b = [0] * 3 + [1] + [1] * 8 + [0] * 8
    (c,) = [c for c in check_orderings(_support_pairs(a, b), seed=3) if c["claim"].startswith("sctdn >")]
    assert c["p_value"] < 0.01 and c["n_supports"] == 20
    assert c["diff"] == pytest.approx(0.1)
    lo, hi = c["diff_ci95"]
    assert lo <= 0.0 < 0.1 < hi and c["support_verdict"] == "undecided"
    win = [1] * 12 + [0] * 8
    (c,) = [c for c in check_orderings(_support_pairs(win, [0] * 20), seed=3)
            if c["claim"].startswith("sctdn >")]
    assert c["diff_ci95"][0] > 0 and c["support_verdict"] == "shown"
    (c,) = [c for c in check_orderings(_support_pairs([0] * 20, win), seed=3)
            if c["claim"].startswith("sctdn >")]
    assert c["diff_ci95"][1] < 0 and c["support_verdict"] == "reversed"
    # the same seed gives the same interval; the claim's own generator, not the call order
    again = check_orderings(_support_pairs(a, b), seed=3)[0]["diff_ci95"]
    assert again == check_orderings(_support_pairs(a, b), seed=3)[0]["diff_ci95"]
