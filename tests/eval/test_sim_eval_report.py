"""sim_eval's metrics and report carry error bars and paired verdicts (synthetic trials)."""

import numpy as np
import pandas as pd
import pytest

from skt_lib.config import LEVELS
from skt_lib.eval.orderings import check_orderings
from skt_lib.eval.protocol import success_table
from skt_lib.sim.execute import REASONS
from skt_lib.stats import paired_comparisons, success_ci95, support_ci95
from viz.sim_eval_report import write_report

METHODS = ["oracle_floating", "template_only", "sctdn", "kpam"]


def _trials():
    rows = []
    for si in range(8):
        for oi in range(5):
            i = si * 5 + oi
            ok = {"oracle_floating": True, "template_only": i % 2 == 0, "sctdn": i % 10 != 0,
                  "kpam": i == 0}
            for m in METHODS:
                rows.append({"trial_id": f"{m}/{si}/{oi}", "method": m, "support_id": f"s{si}",
                             "object_id": f"o{oi}", "difficulty": LEVELS[si % 2],
                             "category": ("mug", "tool")[oi % 2], "success": ok[m],
                             "failure_reason": "" if ok[m] else REASONS[0]})
    return pd.DataFrame(rows)


def _metrics(trials):
    table, ci = success_table(trials), success_ci95(trials, LEVELS)
    boot = support_ci95(trials, LEVELS, np.random.default_rng(0))
    m = {k: {"success": table[k], "n_trials": 40, "success_ci95": ci[k],
             "success_support_ci95": boot[k],
             "failures_by_reason": {r: int(((trials["method"] == k) &
                                            (trials["failure_reason"] == r)).sum())
                                    for r in REASONS}} for k in METHODS}
    m["paired"] = paired_comparisons(trials, "sctdn")
    m["paper_orderings"] = check_orderings(trials)
    return m


def test_report_shows_intervals_and_paired_verdicts(tmp_path):
    trials = _trials()
    metrics = _metrics(trials)
    assert set(metrics["paired"]) == {"sctdn_vs_oracle_floating", "sctdn_vs_template_only",
                                      "sctdn_vs_kpam"}
    assert metrics["sctdn"]["success_ci95"]["hard"] is None  # no hard supports here
    write_report(tmp_path, trials, trials, metrics, METHODS, [None] * 8, [None] * 5, [], [])
    text = (tmp_path / "report.md").read_text()
    # Table I: sctdn 36/40 = 90.0 %, Wilson [76.9–96.0]
    lo, hi = metrics["sctdn"]["success_ci95"]["all"]
    assert (lo, hi) == (pytest.approx(0.7694, abs=5e-4), pytest.approx(0.9604, abs=5e-4))
    slo, shi = metrics["sctdn"]["success_support_ci95"]["all"]
    assert slo < 0.9 < shi  # the bootstrap over the 8 supports brackets the rate
    assert f"| sctdn | 90.0 [76.9–96.0] ‖ {100 * slo:.1f}–{100 * shi:.1f} |" in text
    assert "100.0 [91.2–100.0]" in text  # oracle_floating 40/40
    # per category: sctdn on mugs = 16/20 → 80.0 [58.4–91.9]
    assert "80.0 [58.4–91.9]" in text
    # per level: counts shown; no trials → a dash
    assert "n = 20" in text and "–, n = 0" in text
    # paired: sctdn beats kpam (36 vs 1 discordant) and template_only, not oracle_floating
    assert "| sctdn vs kpam | 40 | 0 | 36 | 1 |" in text and "sctdn better" in text
    row = next(line for line in text.splitlines() if line.startswith("| sctdn vs oracle_floating"))
    assert "oracle_floating better" not in row and "| 0 | 4 |" in row
    assert row.endswith("| no significant difference |")
    row = next(line for line in text.splitlines() if line.startswith("| sctdn vs template_only"))
    assert row.endswith("| sctdn better |")
    # the one paper ordering both methods of which ran: sctdn (90 %) ≥ template_only (50 %) + 10
    row = next(line for line in text.splitlines() if line.startswith("| sctdn ≥ template_only"))
    assert row.startswith("| sctdn ≥ template_only + 10 points (all levels) | 90.0 | 50.0 | yes | "
                          "40.0 [")
    c = next(c for c in metrics["paper_orderings"] if c["claim"].startswith("sctdn ≥"))
    assert c["n_supports"] == 8 and f"| {c['support_verdict']} | 40 (8) |" in row
