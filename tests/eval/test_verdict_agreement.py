"""tools.verdict_agreement: verdicts matched by trial, later proposals counted apart."""

import pandas as pd

from tools.verdict_agreement import agreement


def _trials(rows):
    return pd.DataFrame([{"trial_id": t, "method": t.split("/")[0], "failure_reason": r,
                          "detail": f"d-{r}"} for t, r in rows])


def test_agreement_counts_changed_verdicts_and_sets_extra_proposals_apart():
    old = _trials([("oracle/s0/o0", ""), ("oracle/s0/o1", "dropped"), ("vatmart/s0/o0", "dropped"),
                   ("vatmart/s0/o0/p1", "")])
    new = _trials([("oracle/s0/o0", ""), ("oracle/s0/o1", "perched"), ("vatmart/s0/o0", ""),
                   ("sctdn/s0/o0", "not_reached")])
    out = agreement(old, new)
    assert out["n_common"] == 3 and out["agreement"] == 1 / 3
    assert out["by_method"] == {"oracle": 0.5, "vatmart": 0.0}
    assert out["only_old"] == ["vatmart/s0/o0/p1"] and out["only_new"] == ["sctdn/s0/o0"]
    assert [(d["trial_id"], d["old"], d["new"]) for d in out["disagreements"]] == [
        ("oracle/s0/o1", "dropped", "perched"), ("vatmart/s0/o0", "dropped", "success")]
    assert agreement(old, old)["agreement"] == 1.0 and not agreement(old, old)["disagreements"]
