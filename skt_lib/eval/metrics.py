"""``reports/sim_eval/metrics.json`` from the trials: per method its success per level
with Wilson intervals, failure reasons, success per object category (and, for proposing
methods, the single-proposal rate); paired comparisons; the paper's orderings."""

import numpy as np
import pandas as pd

from skt_lib.config import LEVELS, OBJECT_CATEGORIES
from skt_lib.eval.methods import PROPOSING
from skt_lib.eval.orderings import check_orderings, explain
from skt_lib.eval.protocol import SINGLE, success_table
from skt_lib.seeding import item_rng
from skt_lib.sim.execute import REASONS
from skt_lib.stats import paired_comparisons, success_ci95, support_ci95


def sim_metrics(trials: pd.DataFrame, pairs: pd.DataFrame, methods, n_proposals: int,
                plans: dict | None = None, seed: int = 0) -> dict:
    """The metrics of one evaluation (``trials``: one row per simulated trial; ``pairs``:
    :func:`~skt_lib.eval.protocol.per_pair` of them; ``plans``: ``omnihang``'s plan per
    support, for its ``plan_solved_rate``; ``seed``: the bootstraps' over test supports)."""
    table = success_table(pairs)
    ci95 = success_ci95(pairs, LEVELS)
    support_ci = support_ci95(pairs, LEVELS, item_rng(seed, "sim_eval/bootstrap", "success"))
    metrics = {}
    for m in methods:
        g = pairs[pairs["method"] == m]
        metrics[m] = {"success": table[m], "n_trials": len(g),
                      "n_sim_runs": int((trials["method"] == m).sum()),
                      "failures_by_reason": {r: int((g["failure_reason"] == r).sum())
                                             for r in REASONS},
                      "success_ci95": ci95[m], "success_support_ci95": support_ci[m],
                      "success_by_category": by_category(g)}
        if m in PROPOSING:
            metrics[m] |= {"success_single": table[m + SINGLE],
                           "success_single_ci95": ci95[m + SINGLE],
                           "success_single_support_ci95": support_ci[m + SINGLE],
                           "n_proposals": n_proposals}
        if m == "omnihang" and plans:
            metrics[m] |= {"plan_solved_rate": float(np.mean([x.solved for x in plans.values()]))}
    metrics["paired"] = paired_comparisons(pairs, "sctdn")
    for ref, other in (("vatmart_mod", "vatmart"), ("vatmart_mod" + SINGLE, "vatmart" + SINGLE)):
        sub = pairs[pairs["method"].isin([ref, other])]
        metrics["paired"] |= paired_comparisons(sub, ref) if other in set(sub["method"]) else {}
    metrics["paper_orderings"] = paper_orderings(pairs, metrics, seed)
    return metrics


def by_category(trials: pd.DataFrame) -> dict:
    """Success rate per object category (null where the category has no trial)."""
    return {c: (float(g["success"].mean()) if len(g := trials[trials["category"] == c]) else None)
            for c in OBJECT_CATEGORIES}



def paper_orderings(pairs: pd.DataFrame, metrics: dict, seed: int = 0) -> list[dict]:
    """The paper's orderings on all pairs, each with the same check on the pairs the oracle
    hung (``on_oracle_hung``) and, where it does not hold, an ``explanation``."""
    checks = check_orderings(pairs, seed=seed)
    if "oracle" not in metrics:
        return checks
    oracle = pairs[pairs["method"] == "oracle"].set_index(["support_id", "object_id"])["success"]
    hung = {c["claim"]: c for c in check_orderings(pairs, within=oracle.astype(bool), seed=seed)}
    for c in checks:
        c["on_oracle_hung"] = {k: hung[c["claim"]][k] for k in
                               ("rate_a", "rate_b", "holds", "n_pairs", "p_value", "diff_ci95",
                                "support_verdict")} \
            if c["claim"] in hung else None
        c["explanation"] = explain(c, metrics["oracle"]["success"][c["level"]],
                                   c["on_oracle_hung"])
    return checks
