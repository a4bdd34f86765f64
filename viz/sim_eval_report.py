"""``reports/sim_eval/report.md``: Table I with intervals, the paper's rows beside ours,
Table II (ablation), the paper's orderings with their paired evidence, the oracle against its
target, per-category / per-level / per-support tables, failure reasons and figures.

Every figure comes from the trials (``pairs``: one row per method, support and object) and
the metrics computed from them; the only figures typed in are the paper's own
(:data:`PAPER`, :data:`PAPER_ABLATION`), quoted from its Table I and II.
"""

from pathlib import Path

import pandas as pd

from skt_lib.config import LEVELS, OBJECT_CATEGORIES
from skt_lib.coverage import COVER_M
from skt_lib.eval.methods import PROPOSING
from skt_lib.eval.orderings import success_given
from skt_lib.sim.execute import REASONS
from skt_lib.stats import wilson_interval
from viz.figures import bar_chart
from viz.report import Report

#: What the oracle must reach for methods to be told apart (the executor issue).
ORACLE_TARGET, ORACLE_LEVEL_TARGET = 0.90, 0.80

#: The paper's Table I: (inference s, success % all / easy / normal / hard / very hard).
PAPER = {"kpam": ("–", (40.1, 76.0, 54.1, 21.6, 8.8)),
         "omnihang": ("14.29", (40.1, 62.9, 47.7, 34.3, 15.3)),
         "vatmart": ("0.007", (55.2, 84.5, 82.0, 42.0, 12.3)),
         "vatmart_mod": ("0.016", (72.1, 78.8, 89.6, 57.7, 62.4)),
         "sctdn": ("0.009", (83.7, 85.5, 91.7, 79.7, 77.7))}
#: The paper's Table II (success %, all levels): the ablation rows and our methods for them.
PAPER_ABLATION = (("template + contact point", "template_only", 58.2),
                  ("+ contact-point feature, deformation", "sctdn_cp_feature", 73.5),
                  ("+ shape-conditioned feature, deformation (SCTDN)", "sctdn", 83.7))
#: The label of a proposing method's single-SKT row where it is not its first proposal.
SINGLE_LABEL = {"skt_flow": "one SKT (the training objects' pick of its samples)"}



def _pct(x) -> str:
    return "–" if x is None else f"{100 * x:.1f}"


def _pct_ci(rate, ci) -> str:
    """``52.0 [45.1–58.8]``: a success rate (%) with its Wilson 95 % interval."""
    return "–" if rate is None or ci is None else f"{_pct(rate)} [{_pct(ci[0])}–{_pct(ci[1])}]"


def _pct_cis(rate, wilson, support) -> str:
    """``52.0 [45.1–58.8] ‖ 38.0–66.0``: a success rate (%) with its Wilson 95 % interval and
    its interval from the bootstrap over test supports (the unit of evidence)."""
    if rate is None or wilson is None:
        return "–"
    return _pct_ci(rate, wilson) + ("" if support is None
                                    else f" ‖ {_pct(support[0])}–{_pct(support[1])}")


def _rate_ci(success: pd.Series) -> str:
    ci = wilson_interval(int(success.sum()), len(success))
    return _pct_ci(float(success.mean()) if len(success) else None, ci)


def write_report(rep: Path, trials: pd.DataFrame, pairs: pd.DataFrame, metrics: dict, methods,
                  supports, objects, missing, chosen: list[str]) -> Report:
    report = Report("sim_eval", rep)
    n = len(trials)
    report.text(
        f"{len(methods)} methods × {len(supports)} test supports × {len(objects)} objects; "
        f"{n} simulated trials (proposing methods: a later proposal only where the earlier ones "
        "failed); wall-clock times (the run's, each method's inference: median per support, "
        "batch 1) go to the git-ignored run log `logs/sim_eval.json`; `make bench` measures "
        "speed. "
        "A trial: the Panda holds the object at its grasp (fixed keypoint→hand transform), "
        "follows the SKT from ξ_T-1 to ξ_0 (all of it, ≤ 2 mm per command, joint position "
        "control), releases, retreats; gravity is tilted ±y, +x and settled; the strict "
        "predicate (docs/design.md §5) decides. Each method sees one seeded view of each support. "
        + (f"Test supports without a ground-truth SKT, left out: {', '.join(missing)}."
           if missing else ""))
    report.heading("Table I: success rate (%) [Wilson 95 %] ‖ support-bootstrap 95 %")
    rows = []
    for m in methods:
        rows.append([m, *(_pct_cis(metrics[m]["success"][k], metrics[m]["success_ci95"][k],
                                   metrics[m]["success_support_ci95"][k])
                          for k in ("all", *LEVELS))])
        if m in PROPOSING:
            rows.append([f"{m}, {SINGLE_LABEL.get(m, 'first proposal only')}",
                         *(_pct_cis(metrics[m]["success_single"][k],
                                    metrics[m]["success_single_ci95"][k],
                                    metrics[m]["success_single_support_ci95"][k])
                           for k in ("all", *LEVELS))])
        if m in PAPER:
            rows.append([f"paper: {m}", *(f"{v:.1f}" for v in PAPER[m][1])])
    report.table(["method", "All", "Easy", "Normal", "Hard", "Very Hard"], rows)
    report.text("`oracle*`, `kpam` and `omnihang` are privileged (ground-truth SKTs / hanging "
                "keypoint / hanging pose). `vatmart*` and `skt_flow` rows count a (support, object) "
                "pair as hung if any of its proposals hung it, as the paper did; the 'first "
                "proposal only' rows are the honest single-sample rate, and `skt_flow`'s 'one "
                "SKT' row executes the one of its samples (each moved clear of the observed "
                "points) that the training objects, carried along them, bring least often near "
                "those points; its best of N runs the first N in that order. "
                "Brackets: Wilson 95 % score interval of the rate, as if every pair were "
                "independent; after ‖: the 95 % interval from a bootstrap over test supports "
                f"({len(supports)} in all, {len(supports) // len(LEVELS)} per level; a support's "
                "pairs drawn together). A support's objects mostly hang or fail together, so "
                "the support is the unit of evidence and the second interval is the one to "
                "read; per level it rests on few supports. Paper rows have none. "
                + _omnihang_note(metrics))
    _seeds_section(report, metrics.get("seeds"))
    _ablation_table(report, metrics)
    _coverage_table(report, metrics.get("multimodality_coverage"))
    _orderings(report, metrics["paper_orderings"], pairs)
    _paired_table(report, metrics.get("paired", {}))
    _oracle_target(report, metrics, pairs)
    bar_chart({m: {lv: 100 * (metrics[m]["success"][lv] or 0) for lv in ("all", *LEVELS)}
               for m in methods}, report.figure("success.png", "Success rate (%) per level"),
              "success rate (%)")
    report.heading("Per object category (success %, paper Table III layout)")
    cats = [c for c in OBJECT_CATEGORIES if c in set(pairs["category"])]
    report.table(["method", *cats], [[m, *(_rate_ci(pairs.loc[(pairs["method"] == m)
                                                           & (pairs["category"] == c), "success"])
                                           for c in cats)] for m in methods])
    report.heading("Failure reasons")
    counts = {m: {r: metrics[m]["failures_by_reason"][r] for r in REASONS} for m in methods}
    report.table(["method", *REASONS], [[m, *counts[m].values()] for m in methods])
    bar_chart(counts, report.figure("failures.png", "Failure reasons per method (trial counts)"),
              "failures")
    report.text("`ik_failed`: no grasp candidate lets the hand follow the path within tolerance "
                "(kinematics; `detail` in trials.parquet says which check); "
                "`collided_before_hang`: the object or robot is blocked by the support or wall "
                "on the way in; `not_reached`: released, never touched the support; `dropped`: "
                "touched it, then fell; `not_at_rest`: on the support but still moving at the "
                "end; `on_wall_plate`: resting on the wall plate only; `perched`: rests on top. "
                "The arm leaves the scene after its retreat, so nothing ends on the gripper. "
                "`oracle_floating` has no arm: it cannot fail by `ik_failed`.")
    report.heading("Per level (success % [Wilson 95 %] ‖ support-bootstrap 95 %, trials)")
    n_by_level = pairs.groupby(["method", "difficulty"]).size()
    report.table(["method", *LEVELS],
                 [[m, *(_pct_cis(metrics[m]["success"][lv], metrics[m]["success_ci95"][lv],
                                 metrics[m]["success_support_ci95"][lv])
                        + f", n = {int(n_by_level.get((m, lv), 0))}" for lv in LEVELS)]
                  for m in methods])
    report.heading("Per support")
    per = pairs.pivot_table(index=["support_id", "difficulty"], columns="method", values="success",
                             aggfunc="mean").reset_index()
    report.table(["support", "level", *methods],
                 [[r["support_id"], r["difficulty"], *(_pct(r[m]) for m in methods)]
                  for _, r in per.iterrows()])
    report.recording("trial")
    report.text(f"{len(chosen)} rollouts (robot, object, SKT with its waypoint frames, the "
                "keypoint's executed path, its distance from the SKT): per method one rollout on "
                "each level (a success where there is one) and the first trial of each further "
                "failure reason. The `trial` timeline shows each "
                "trial's end state; scrub `step` to replay a rollout.")
    if "user_items" in metrics:
        from skt_lib.eval.user_items import user_table

        user = metrics["user_items"]
        report.heading("User items (sim_eval.extra_supports / extra_objects; not in Table I)")
        report.text("Every method on every pair with an imported item: "
                    + ", ".join(f"`{k}`" for k in user["records_md5"]) + ".")
        report.table(["method", "pairs", "hung", "success %"], user_table(user, methods))
    report.write()
    return report


def _omnihang_note(metrics: dict) -> str:
    if "omnihang" not in metrics:
        return ""
    o = metrics["omnihang"]
    return (f"`omnihang`'s RRT-Connect found a path on {100 * o['plan_solved_rate']:.0f} % "
            "of the supports (elsewhere the straight approach is executed).")


def _orderings(report: Report, checks: list[dict], pairs: pd.DataFrame) -> None:
    """The paper's orderings on our trials, and each method's success where the oracle's own
    SKT hangs the object (and where it does not)."""
    report.heading("The paper's orderings on these trials")
    def hung(c):
        h = c.get("on_oracle_hung")
        if not h:
            return "–"
        return (f"{_pct(h['rate_a'])} vs {_pct(h['rate_b'])}, "
                f"{'holds' if h['holds'] else 'does not hold'} ({h['support_verdict']}; "
                f"p {h['p_value']:.3g})")

    report.table(["claim", "A %", "B %", "holds", "A − B, points [support 95 %]", "verdict",
                  "pairs (supports)", "A only / B only", "McNemar p", "oracle-hung pairs"],
                 [[c["claim"], _pct(c["rate_a"]), _pct(c["rate_b"]), "yes" if c["holds"] else "no",
                   f"{_pct(c['diff'])} [{_pct(c['diff_ci95'][0])}, {_pct(c['diff_ci95'][1])}]",
                   c["support_verdict"], f"{c['n_pairs']} ({c['n_supports']})",
                   f"{c['n_a_only']} / {c['n_b_only']}", f"{c['p_value']:.3g}",
                   hung(c)] for c in checks])
    report.text("Same (support, object) pairs for A and B; `vatmart*` counted best-of-N as in the "
                "paper. 'holds' compares the rates; the verdict judges the claim on the 95 % "
                "interval of A − B from a bootstrap over test supports (a support's pairs drawn "
                "together): `shown` where the whole interval clears the claim's margin, "
                "`reversed` where it lies wholly on the other side, `undecided` otherwise. "
                "McNemar's p treats pairs as independent and overstates the evidence where a "
                "support's objects fail together; 'oracle-hung' repeats the check on the pairs "
                "the oracle's own SKT hangs.")
    why = [c["explanation"] for c in checks if c.get("explanation")]
    if why:
        report.text("Where an ordering does not hold, or holds vacuously: " + " ".join(why))
    given = success_given(pairs, "oracle")
    if not given:
        return
    report.heading("Success where the oracle's SKT hangs the object, and where it does not")
    report.table(["method", "on oracle-hung pairs", "n", "on oracle-failed pairs", "n"],
                 [[m, _pct(g["on_ref_ok"]), g["n_ref_ok"], _pct(g["on_ref_failed"]),
                   g["n_ref_failed"]] for m, g in given.items() if m != "oracle"])
    report.text("The oracle executes a ground-truth SKT with the same arm, grasps and predicate: "
                "a pair it fails is one where the executor or the data (not the method's "
                "prediction) is the limit, so methods are best told apart on the oracle-hung "
                "pairs. A method above the oracle on its failed pairs finds SKTs that none of "
                "the support's stored ground-truth SKTs gives the arm.")


def _seeds_section(report: Report, seeds: dict | None) -> None:
    """Table I's learned methods over the training seeds, mean [min–max], and the paper's
    orderings judged on the mean with each seed's McNemar test."""
    report.heading("Table I over training seeds: success % mean [min–max]")
    if not seeds or seeds["status"] != "ok":
        report.text("Not merged: " + (seeds["reason"] if seeds else "no seed runs") + ".")
        return
    def span(b: dict, f: str, k: str) -> str:
        if b[f + "_mean"][k] is None:
            return "–"
        return f"{_pct(b[f + '_mean'][k])} [{_pct(b[f + '_min'][k])}–{_pct(b[f + '_max'][k])}]"

    rows = []
    for m, b in seeds.items():
        if not isinstance(b, dict) or "success_mean" not in b:
            continue
        rows.append([m, *(span(b, "success", k) for k in ("all", *LEVELS))])
        if "success_single_mean" in b:
            rows.append([f"{m}, first proposal only",
                         *(span(b, "success_single", k) for k in ("all", *LEVELS))])
    report.table(["method", "All", "Easy", "Normal", "Hard", "Very Hard"], rows)
    report.text(f"Training seeds {', '.join(map(str, seeds['seeds']))} (the first is this run's "
                "`common.seed`; the others' outcomes come from `reports/seeds/seed_runs.json`, "
                "made by `make seeds` from the same data, code and params, and evaluated on the "
                "same trials): the spread is the training seed's alone.")
    rows = []
    for c in seeds["paper_orderings"]:
        per = c["per_seed"].values()
        ci = c["diff_ci95"]
        rows.append([c["claim"], _pct(c["rate_a_mean"]), _pct(c["rate_b_mean"]),
                     "yes" if c["holds"] else "no", f"{c['holds_on_seeds']} / {len(per)}",
                     f"{_pct(c['diff_mean'])} [{_pct(ci[0])}, {_pct(ci[1])}]" if ci else "–",
                     ", ".join(f"{x['n_a_only']}/{x['n_b_only']}" for x in per),
                     ", ".join(f"{x['p_value']:.2g}" for x in per)])
    report.table(["claim", "A % mean", "B % mean", "holds (mean)", "seeds where it holds",
                  "A − B, points [95 %]", "A only / B only per seed", "McNemar p per seed"],
                 rows)
    report.text("A − B: the difference of the mean rates, with a 95 % interval from a bootstrap "
                "over test supports (a support's pairs drawn together, every seed's outcome on "
                "them): trials on one support are correlated, so supports are the unit. "
                "McNemar per seed on the same pairs; 'holds' compares the mean rates, with the "
                "margin where the claim has one.")


def _coverage_table(report: Report, cov: dict | None) -> None:
    """Multimodality: the share of a test support's ground-truth SKTs a method's samples
    reach (:mod:`skt_lib.coverage`), per level."""
    if not cov:
        return
    report.heading("Multimodality: ground-truth SKTs reached (%)")
    report.table(["method", "samples", "All", "Easy", "Normal", "Hard", "Very Hard"],
                 [[m, c["n_samples"], *("–" if c[k] is None else f"{100 * c[k]:.1f}"
                                        for k in ("all", *LEVELS))] for m, c in cov.items()])
    report.text(f"Per test support, the share of its stored ground-truth SKTs (the oracle's "
                f"choices) that at least one of the method's first samples comes within "
                f"{1000 * COVER_M:.0f} mm of (mean waypoint distance), averaged over the "
                "supports of a level. A single-SKT method reaches at most one of them.")


def _ablation_table(report: Report, metrics: dict) -> None:
    """Table II: the ablation rows (ours where evaluated) beside the paper's."""
    report.heading("Table II: ablation (success %, all levels) [Wilson 95 %] ‖ support-bootstrap 95 %")
    report.table(["design", "method", "ours", "paper"],
                 [[d, m, _pct_cis(metrics[m]["success"]["all"], metrics[m]["success_ci95"]["all"],
                                  metrics[m]["success_support_ci95"]["all"])
                   if m in metrics else "not evaluated", f"{v:.1f}"] for d, m, v in PAPER_ABLATION])


def _oracle_target(report: Report, metrics: dict, pairs: pd.DataFrame) -> None:
    """How far the oracle is from its target, and its failures per level for each hand (the
    floating hand: what the SKTs allow; the arm: what the Panda adds)."""
    if "oracle" not in metrics:
        return
    o = metrics["oracle"]
    short = [lv for lv in LEVELS if (o["success"][lv] or 0.0) < ORACLE_LEVEL_TARGET]
    gap = ORACLE_TARGET - o["success"]["all"]
    report.heading("Oracle against its target")
    report.text(
        f"Target: oracle ≥ {100 * ORACLE_TARGET:.0f} % overall and ≥ "
        f"{100 * ORACLE_LEVEL_TARGET:.0f} % per level. Overall: "
        + (f"{100 * gap:.1f} points below the target" if gap > 0 else "met")
        + (f"; levels below target: {', '.join(short)}" if short else "") + ".")
    rows = []
    for method in ("oracle_floating", "oracle"):
        g = pairs[pairs["method"] == method]
        for lv in LEVELS:
            sub = g[g["difficulty"] == lv]
            if len(sub):
                counts = sub.loc[~sub["success"], "failure_reason"].value_counts()
                other = int(sub["grasp"].str.match(r"skt\d+/").sum())
                rows.append([method, lv, len(sub), _pct(float(sub["success"].mean())),
                             ", ".join(f"{r} {n}" for r, n in counts.items()) or "–", other])
    report.table(["method (hand)", "level", "trials", "success %", "failures",
                  "ran another stored SKT"], rows)
    report.text("The oracles choose among the support's stored ground-truth SKTs at set-up "
                "(the first the test object sweeps clear, else the one it penetrates least, "
                "that, for the arm, a grasp can follow; "
                "docs/evaluation.md); the last column counts the trials that did not run the "
                "first stored SKT.")


def _paired_table(report: Report, paired: dict) -> None:
    """The paired comparisons (same trials, exact McNemar): "A beats B" only where it holds."""
    report.heading("Paired comparisons (same support × object trials, exact McNemar, α = 0.05)")
    if not paired:
        report.text("No paired comparisons: `sctdn` was not evaluated.")
        return
    rows = []
    for key, c in paired.items():
        a, b = key.split("_vs_", 1)
        verdict = {"A better": f"{a} better", "B better": f"{b} better"}.get(c["verdict"],
                                                                             c["verdict"])
        rows.append([f"{a} vs {b}", c["n_pairs"], c["n_both"], c["n_a_only"], c["n_b_only"],
                     f"{c['p_value']:.3g}", verdict])
    report.table(["comparison", "pairs", "both ok", "A only", "B only", "p", "verdict"], rows)
    report.text("A only / B only: trials only the first / second method hung. The verdict "
                "names a winner only where p < 0.05; otherwise the difference in Table I is "
                "not evidence that one method beats the other.")
