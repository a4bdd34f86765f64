"""tools.seed_compare: two rows of Table I over training seeds, per level, on the pairs
sim_eval ran and the extra seeds' outcomes it would merge."""

import json

import pandas as pd
import pytest
import yaml

from skt_lib.errors import DataError
from skt_lib.eval.seeds import inputs_key, runs_document
from tools.seed_compare import compare, markdown, merge_seeds

LEVELS = ["easy"] * 4 + ["very_hard"] * 4
BASE = 7
RUN = {7: {"skt_flow@1": [1, 1, 0, 0, 1, 0, 0, 0], "vatmart_mod": [1, 1, 1, 1, 1, 1, 0, 0]},
       8: {"skt_flow@1": [1, 1, 1, 0, 0, 0, 0, 0], "vatmart_mod": [1, 0, 1, 1, 1, 1, 1, 0]},
       9: {"skt_flow@1": [1, 1, 1, 1, 1, 1, 1, 1], "vatmart_mod": [0, 0, 0, 0, 1, 1, 1, 1]}}


def _pairs(flags: dict[str, list[int]]) -> pd.DataFrame:
    return pd.DataFrame([{"method": m, "support_id": f"s{i // 2}", "object_id": f"o{i % 2}",
                          "difficulty": lv, "success": bool(v), "failure_reason": ""}
                         for m, ok in flags.items() for i, (v, lv) in enumerate(zip(ok, LEVELS))])


@pytest.fixture
def repo(tmp_path):
    (tmp_path / "params.yaml").write_text("common: {seed: 7}\n")
    (tmp_path / "dvc.yaml").write_text(yaml.safe_dump({"stages": {"sim_eval": {"deps": []}}}))
    (tmp_path / "dvc.lock").write_text(yaml.safe_dump({"schema": "2.0", "stages": {}}))
    return tmp_path


def _runs(repo, key=None):
    path = repo / "reports/seeds/seed_runs.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(runs_document(key or inputs_key(repo),
                                             {s: _pairs(RUN[s]) for s in (8, 9)})))
    return path


def test_each_seed_keeps_its_own_outcomes_and_the_levels_are_compared_over_seeds(repo):
    by_seed = merge_seeds(_pairs(RUN[BASE]), BASE, _runs(repo), repo)
    assert list(by_seed) == [7, 8, 9]
    for s, p in by_seed.items():  # every seed's flags, pair for pair, as its run had them
        for m, flags in RUN[s].items():
            assert p[p["method"] == m]["success"].astype(int).tolist() == flags
    rows = {r["level"]: r for r in compare(by_seed, "skt_flow@1", "vatmart_mod", BASE)}
    assert list(rows) == ["all", "easy", "very_hard"]  # levels without pairs are left out
    e, v = rows["easy"], rows["very_hard"]
    assert e["rate_a_mean"] == pytest.approx((0.5 + 0.75 + 1.0) / 3)
    assert e["rate_b_mean"] == pytest.approx((1.0 + 0.75 + 0.0) / 3)
    assert v["rate_a_mean"] == pytest.approx((0.25 + 0.0 + 1.0) / 3)
    assert [v["per_seed"][s]["n_b_only"] for s in ("7", "8", "9")] == [1, 3, 0]
    assert e["holds_on_seeds"] == 1 and not v["holds"]  # easy: seed 9 (8 ties: strict)
    lo, hi = rows["all"]["diff_ci95"]
    assert lo <= rows["all"]["diff_mean"] <= hi
    assert "| easy | 75.0 | 58.3 | +16.7 [" in markdown(list(rows.values()))


def test_seeds_sim_eval_would_not_merge_are_refused(repo):
    with pytest.raises(DataError, match="make seeds"):  # missing
        merge_seeds(_pairs(RUN[BASE]), BASE, repo / "reports/seeds/seed_runs.json", repo)
    path = _runs(repo, key="0" * 64)
    with pytest.raises(DataError, match="other inputs"):
        merge_seeds(_pairs(RUN[BASE]), BASE, path, repo)
    by_seed = merge_seeds(_pairs(RUN[BASE]), BASE, _runs(repo), repo)
    with pytest.raises(DataError, match="sctdn"):
        compare(by_seed, "sctdn", "vatmart_mod", BASE)
