"""The orderings the paper reports (Table I and II), checked on our trials with their
paired evidence, and success conditioned on what the privileged oracle can do."""

import pandas as pd

from skt_lib.seeding import item_rng
from skt_lib.stats import paired_comparison, paired_support_interval

#: (claim, A, B, level, margin, strict): "A > B + margin" (strict) or "A ≥ B + margin" on
#: ``level`` ("all": pooled), as the paper's Table I and II order them.
PAPER_ORDERINGS = (
    ("sctdn > vatmart_mod (all levels)", "sctdn", "vatmart_mod", "all", 0.0, True),
    ("vatmart_mod > vatmart (all levels)", "vatmart_mod", "vatmart", "all", 0.0, True),
    ("sctdn ≥ template_only + 10 points (all levels)", "sctdn", "template_only", "all", 0.10,
     False),
    ("Very Hard: sctdn ≥ vatmart_mod", "sctdn", "vatmart_mod", "very_hard", 0.0, False),
)


#: Verdicts of an ordering on the support-bootstrap interval of A − B against its margin.
SHOWN, REVERSED, UNDECIDED = "shown", "reversed", "undecided"


def check_orderings(pairs: pd.DataFrame, orderings=PAPER_ORDERINGS,
                    within: pd.Series | None = None, seed: int = 0) -> list[dict]:
    """For each ordering whose methods both ran: rates of A and B on the same (support,
    object) pairs of the level, whether it holds, the exact McNemar test of A against B on
    those pairs, and the 95 % interval of A − B from a bootstrap over test supports
    (``diff_ci95``; drawn by ``item_rng(seed, "sim_eval/bootstrap", claim)``) with its verdict: ``shown`` when the whole
    interval clears the margin (strictly where the claim is strict), ``reversed`` when it
    lies wholly on the other side, else ``undecided``. ``pairs``: one row per (method,
    support, object) (:func:`skt_lib.eval.protocol.per_pair`); ``within``: a boolean Series
    on (support_id, object_id) keeping only the pairs where it is true (e.g. those the
    oracle hung)."""
    if within is not None:
        keep = pd.MultiIndex.from_frame(pairs[["support_id", "object_id"]]).isin(
            within[within].index)
        pairs = pairs[keep]
    out = []
    for claim, a, b, level, margin, strict in orderings:
        sub = pairs if level == "all" else pairs[pairs["difficulty"] == level]
        fa, fb = (_flags(sub, m) for m in (a, b))
        if fa is None or fb is None:
            continue
        fa, fb = fa.align(fb, join="inner")
        if not len(fa):
            continue
        ra, rb = float(fa.mean()), float(fb.mean())
        gap = ra - rb - margin
        holds = gap > 1e-12 if strict else gap >= -1e-12  # 0.6 + 0.1 must reach 0.7
        c = paired_comparison(fa.to_numpy(), fb.to_numpy())
        ci = paired_support_interval(fa.to_numpy(), fb.to_numpy(),
                                     fa.index.get_level_values("support_id").to_numpy(),
                                     item_rng(seed, "sim_eval/bootstrap", claim))
        out.append({"claim": claim, "a": a, "b": b, "level": level, "rate_a": ra, "rate_b": rb,
                    "holds": bool(holds), "n_pairs": c.n_pairs, "n_a_only": c.n_a_only,
                    "n_b_only": c.n_b_only, "p_value": c.p_value,
                    "verdict": c.verdict, "diff": ra - rb, "diff_ci95": list(ci),
                    "n_supports": int(fa.index.get_level_values("support_id").nunique()),
                    "support_verdict": _support_verdict(ci, margin, strict)})
    return out


def _support_verdict(ci: tuple[float, float], margin: float, strict: bool) -> str:
    lo, hi = ci
    if lo > margin or (not strict and lo >= margin - 1e-12):
        return SHOWN
    if hi < margin or (strict and hi <= margin + 1e-12):
        return REVERSED
    return UNDECIDED


def explain(check: dict, oracle_rate: float | None, on_oracle_hung: dict | None) -> str:
    """One sentence on an ordering that does not hold, or holds only because neither method
    hangs anything, from the figures alone: the oracle's ceiling on the level, the evidence
    (McNemar p) and the ordering on the pairs the oracle hung (``on_oracle_hung``: the same
    check restricted to them, or ``None``)."""
    pct = lambda x: f"{100 * x:.1f} %"  # noqa: E731
    if check["rate_a"] == check["rate_b"] == 0 and oracle_rate is not None:
        return (f"{check['claim']}: " + ("holds only because " if check["holds"] else "")
                + f"neither hangs any of these {check['n_pairs']} pairs; the "
                f"oracle's own SKT hangs {pct(oracle_rate)} of them"
                + (" — nothing to rank: the executor and the data are the limit here, not "
                   "the methods." if oracle_rate == 0 else "."))
    if check["holds"]:
        return ""
    text = (f"{check['claim']}: {pct(check['rate_a'])} vs {pct(check['rate_b'])}, "
            f"{check['n_a_only']} pairs only A hung, {check['n_b_only']} only B (McNemar p = "
            f"{check['p_value']:.3g}: " + ("a significant reversal" if check["p_value"] < 0.05
                                           else "no significant difference") + ")")
    if on_oracle_hung:
        text += (f"; on the {on_oracle_hung['n_pairs']} pairs the oracle hangs: "
                 f"{pct(on_oracle_hung['rate_a'])} vs {pct(on_oracle_hung['rate_b'])} "
                 f"(p = {on_oracle_hung['p_value']:.3g})")
    return text + "."


def _flags(pairs: pd.DataFrame, method: str):
    g = pairs[pairs["method"] == method]
    if g.empty:
        return None
    return g.set_index(["support_id", "object_id"])["success"].astype(bool)


def success_given(pairs: pd.DataFrame, reference: str) -> dict[str, dict]:
    """Per method, its success rate on the pairs ``reference`` hung and on those it did not:
    ``{method: {"n_ref_ok", "on_ref_ok", "n_ref_failed", "on_ref_failed"}}`` (rates ``None``
    where there are no such pairs). With ``reference`` the oracle, the first rate separates
    a method's own errors from trials that fail even along the ground-truth SKT."""
    ref = _flags(pairs, reference)
    if ref is None:
        return {}
    out = {}
    for method in dict.fromkeys(pairs["method"]):
        f, r = _flags(pairs, method).align(ref, join="inner")
        ok, bad = f[r], f[~r]
        out[method] = {"n_ref_ok": int(len(ok)), "on_ref_ok": float(ok.mean()) if len(ok) else None,
                       "n_ref_failed": int(len(bad)),
                       "on_ref_failed": float(bad.mean()) if len(bad) else None}
    return out
