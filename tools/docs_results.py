"""Write the figures a run produced into README.md and docs/*.md, from the committed reports.

Every such figure sits in a block between ``<!-- NAME:start -->`` and ``<!-- NAME:end -->``
and is written here from ``reports/sim_eval/metrics.json`` and ``reports/bench/bench.json``;
nothing between the markers is typed by hand. The last step of ``make repro`` and
``make bench``; ``tests/test_docs.py`` checks that the committed blocks are current.

    .venv/bin/python -m tools.docs_results           # rewrite the blocks in place
    .venv/bin/python -m tools.docs_results --check   # exit 1, with a diff, if one is stale
"""

import argparse
import difflib
import json
import sys
from pathlib import Path

from skt_lib.config.sim_eval import METHODS
from tools import scaling
from viz.sim_eval_report import PAPER as PAPER_ROWS

ROOT = Path(__file__).resolve().parents[1]
METRICS = Path("reports/sim_eval/metrics.json")
BENCH = Path("reports/bench/bench.json")
SCALING = Path("reports/bench/scaling.json")  # optional: written by `python -m tools.scaling`
PAPER_METRICS = Path("reports/paper/sim_eval/metrics.json")  # optional: `make paper`'s

LEVELS = (("all", "All"), ("easy", "Easy"), ("normal", "Normal"), ("hard", "Hard"),
          ("very_hard", "Very Hard"))

# bench.json: key -> (format of the value with its unit, meaning). Every key the bench
# writes has a row here (tests/test_docs.py checks it); the bench's sample sizes go into
# the sentence above the table.
BENCH_ROWS = {
    "rrt_plan_s_median": ("{:.2f} s", "planning time per SKT attempt (one process per support)"),
    "rrt_recheck_s_median": ("{:.2f} s", "independent re-check time per SKT"),
    "rrt_skts_per_min": ("{:.0f}", "SKTs planned and re-checked per minute of wall time, "
                                   "`compute.n_workers` workers: the one-tree planner"),
    "rrt_plan_s_median_reference": ("{:.2f} s", "planning time per SKT attempt, the per-SKT "
                                                "reference planner (a fresh search per SKT, every "
                                                "obstacle queried at every pose)"),
    "rrt_recheck_s_median_reference": ("{:.2f} s", "re-check time per SKT, the reference's SKTs"),
    "rrt_skts_per_min_reference": ("{:.0f}", "the same supports and SKT count with the "
                                             "reference planner, same run"),
    "rrt_speedup_vs_reference_planner": ("{:.1f}×", "the one-tree planner's SKTs per minute over "
                                                    "the reference's, same run"),
    "rrt_diversity_mm": ("{}", "mean pairwise distance (mm) of a support's SKTs (T waypoints), "
                               "per level: the one-tree planner"),
    "rrt_diversity_mm_reference": ("{}", "the same for the reference planner"),
    "render_ms_per_view_median": ("{:.1f} ms", "ray casting of one view (Open3D), one process"),
    "render_total_ms_per_view_median": ("{:.1f} ms", "the whole view: ray casting, farthest-"
                                                     "point sampling to N, shuffle, NPZ write; "
                                                     "one process"),
    "sctdn_inference_ms_median": ("{:.1f} ms", "SCTDN, batch 1, one rendered view in → SKT out, "
                                               "model loaded; median of 100 after 10 warm-up"),
    "skt_flow_inference_ms_median": ("{:.1f} ms", "skt_flow, batch 1, one rendered view in → "
                                                  "its `sim_eval.flow_samples` samples, each "
                                                  "moved clear of the points and ordered by the "
                                                  "training objects carried along them (the "
                                                  "first: the SKT it runs), model loaded; "
                                                  "median of 100 after 10 warm-up"),
    "skt_flow_sample_ms_median": ("{:.1f} ms", "of which drawing the samples (the network, "
                                               "three contacts, the cloud check's order)"),
    "skt_flow_clear_ms_median": ("{:.1f} ms", "of which moving each clear of the points "
                                              "(`skt_lib/eval/clear_shift.py`)"),
    "skt_flow_order_ms_median": ("{:.1f} ms", "of which ordering them by the training objects "
                                              "(`skt_lib/eval/probe_check.py`)"),
    "cli_predict_ms_median": ("{:.0f} ms", "`skt predict`'s prediction of a 1000-point view: "
                                           "cleaning, sampling, skt_flow (the default "
                                           "model); model loaded, process start excluded; "
                                           "median of 30 after 3 warm-up"),
    "sim_trials_per_min": ("{:.0f}", "`sim_eval` trials (Panda; the oracle's and SCTDN's SKTs, "
                                     "every test object) per minute of wall time, "
                                     "`compute.n_workers` workers, the default executor "
                                     "(`rest_exit`: also ends the settle once the object is at "
                                     "rest)"),
    "sim_trials_per_min_previous": ("{:.0f}", "the same trials with the executor before it "
                                              "(`fallen_exit`), same run"),
    "sim_trials_per_min_reference": ("{:.0f}", "the same trials with the reference executor "
                                               "(numpy IK, the Panda's visual meshes loaded, "
                                               "every physics step), same run"),
    "sim_speedup_vs_previous_executor": ("{:.2f}×", "the default executor's trials per minute "
                                                    "over the previous one's"),
    "sim_speedup_vs_reference_executor": ("{:.2f}×", "the default executor's trials per minute "
                                                     "over the reference executor's"),
    "sim_verdict_agreement": ("{:.3f}", "share of those trials whose verdict (failure reason, "
                                        "or success) the default executor and the reference "
                                        "agree on"),
    "sim_verdict_agreement_previous": ("{:.3f}", "the same for the previous executor"),
    "sim_success_agreement": ("{:.3f}", "share of those trials whose outcome alone (hung or "
                                        "not) the default executor and the reference agree on"),
    "sim_success_agreement_previous": ("{:.3f}", "the same for the previous executor"),
    "import_dense_s_median": ("{:.1f} s", "`skt import-support` / `import-object` of a ≥ 250k-"
                                          "face mesh (the mesh zoo's dense cases, "
                                          "`skt_lib/cli/mesh_zoo.py`), process start included"),
    "import_dense_s": ("{}", "each of those imports (s)"),
}
BENCH_SAMPLE = ("machine", "rrt_bench_supports", "rrt_bench_skts", "rrt_bench_skts_reference",
                "rrt_bench_skts_per_support", "sim_bench_trials", "sim_bench_executor",
                "sim_bench_setup_failures_excluded",
                "sim_bench_failures_reference", "sim_verdict_disagreements",
                "sim_verdict_disagreements_previous", "import_dense_failed", "parts_commit")

PAPER_SKTS = 472 * 50  # the paper preset of docs/presets.md: supports × SKTs per support


class DocsError(Exception):
    """An expected failure: a missing report or marker. The message names the file."""


def load_reports(root: Path = ROOT) -> dict:
    """``{"metrics": sim_eval's metrics.json, "bench": bench.json, "scaling": scaling.json
    or {}}`` under ``root``."""
    out = {}
    for key, rel in (("metrics", METRICS), ("bench", BENCH)):
        path = root / rel
        if not path.is_file():
            raise DocsError(f"{rel}: not found (written by `make repro` / `make bench`)")
        try:
            out[key] = json.loads(path.read_text())
        except json.JSONDecodeError as err:
            raise DocsError(f"{rel}: not valid JSON: {err}") from None
    for key, rel in (("scaling", SCALING), ("paper", PAPER_METRICS)):
        path = root / rel
        out[key] = json.loads(path.read_text()) if path.is_file() else {}
    return out


def _pct(value: float | None) -> str:
    return "–" if value is None else f"{100 * value:.1f}"


def table_methods(metrics: dict) -> list[str]:
    """Methods with a ``success`` dict: the order of ``sim_eval.methods`` (the paper's
    Table I), then any other in the file's order."""
    present = [m for m, v in metrics.items()
               if isinstance(v, dict) and isinstance(v.get("success"), dict)]
    return [m for m in METHODS if m in present] + [m for m in present if m not in METHODS]


def table_one(metrics: dict) -> str:
    """Table I: success rate (%) per method and difficulty level; "–" where undefined."""
    lines = []
    if "n_test_supports" in metrics and "n_test_objects" in metrics:
        lines += [f"Success rate (%) on {metrics['n_test_supports']} test supports × "
                  f"{metrics['n_test_objects']} test objects, one trial per pair and method; "
                  "brackets: the 95 % interval of All from a bootstrap over test supports (a "
                  "support's objects mostly hang or fail together: the support is the unit).",
                  ""]
    lines += ["| method | " + " | ".join(title for _, title in LEVELS) + " |",
              "|---" * (len(LEVELS) + 1) + "|"]
    def row(label: str, success: dict, ci: dict) -> str:
        cells = [_pct(success.get(k)) for k, _ in LEVELS]
        if ci.get("all") and success.get("all") is not None:
            cells[0] += f" [{_pct(ci['all'][0])}–{_pct(ci['all'][1])}]"
        return f"| {label} | " + " | ".join(cells) + " |"

    for m in table_methods(metrics):
        e = metrics[m]
        best_of = f" (best of {e['n_proposals']})" if "success_single" in e else ""
        lines.append(row(f"`{m}`{best_of}", e["success"], e.get("success_support_ci95") or {}))
        if "success_single" in e:  # a proposing method's one-SKT rate, the honest one
            lines.append(row(f"`{m}`, one SKT", e["success_single"],
                             e.get("success_single_support_ci95") or {}))
    seeds = metrics.get("seeds")
    if seeds and seeds.get("status") == "ok":
        lines += ["", f"The learned methods over training seeds {', '.join(map(str, seeds['seeds']))} "
                  "(`make seeds`; same data and trials), success % mean [min–max]:", "",
                  "| method | " + " | ".join(title for _, title in LEVELS) + " |",
                  "|---" * (len(LEVELS) + 1) + "|"]
        for m, b in seeds.items():
            if isinstance(b, dict) and "success_mean" in b:
                lines.append(f"| `{m}` | " + " | ".join(
                    "–" if b["success_mean"][k] is None else
                    f"{_pct(b['success_mean'][k])} [{_pct(b['success_min'][k])}–"
                    f"{_pct(b['success_max'][k])}]" for k, _ in LEVELS) + " |")
    elif seeds:
        lines += ["", f"Over training seeds: not merged ({seeds['reason']})."]
    return "\n".join(lines)


def _seed_cell(metrics: dict, method: str, key: str = "success") -> str:
    """All over training seeds, mean [min–max]; ``key``: ``success`` or ``success_single``
    (a proposing method's first proposal)."""
    b = (metrics.get("seeds") or {}).get(method)
    if not isinstance(b, dict) or f"{key}_mean" not in b or b[f"{key}_mean"]["all"] is None:
        return "–"
    return (f"{_pct(b[f'{key}_mean']['all'])} [{_pct(b[f'{key}_min']['all'])}–"
            f"{_pct(b[f'{key}_max']['all'])}]")


def paper_table_one(paper: dict, default: dict) -> str:
    """Table I of the paper preset's run (``make paper``), with the SKT-Hang paper's published
    All and the embedded default's All beside each row, and the learned methods over
    training seeds when the seed step merged."""
    seeds = paper.get("seeds") or {}
    merged = seeds.get("status") == "ok"
    lines = [f"Success rate (%) at the paper's scale (`make paper`, "
             f"[reports/paper](reports/paper/README.md)): {paper['n_test_supports']} test "
             f"supports × {paper['n_test_objects']} test objects, one trial per pair and method; "
             "brackets: the 95 % interval of a bootstrap over test supports (the unit of "
             "evidence). *SKT-Hang*: the paper's published All; *default*: the "
             "embedded default's All (20 test supports, `make repro`)"
             + (f"; *seeds*: All over training seeds {', '.join(map(str, seeds['seeds']))}, "
                "mean [min–max]." if merged else "."), "",
             "| method | " + " | ".join(title for _, title in LEVELS) + " | SKT-Hang | default"
             + (" | seeds |" if merged else " |"),
             "|---" * (len(LEVELS) + 3 + merged) + "|"]

    def row(label: str, m: str, key: str) -> str:
        e = paper[m]
        success, ci = e[key], e.get(f"{key}_support_ci95") or {}
        cells = [_pct(success.get(k)) for k, _ in LEVELS]
        if ci.get("all") and success.get("all") is not None:
            cells[0] += f" [{_pct(ci['all'][0])}–{_pct(ci['all'][1])}]"
        published = PAPER_ROWS.get(m) if key == "success" else None
        cells.append("–" if published is None else f"{published[1][0]:.1f}")
        d = (default.get(m) or {}).get(key) or {}
        cells.append(_pct(d.get("all")))
        if merged:
            cells.append(_seed_cell(paper, m, key))
        return f"| {label} | " + " | ".join(cells) + " |"

    for m in table_methods(paper):
        e = paper[m]
        best_of = f" (best of {e['n_proposals']})" if "success_single" in e else ""
        lines.append(row(f"`{m}`{best_of}", m, "success"))
        if "success_single" in e:
            lines.append(row(f"`{m}`, one SKT", m, "success_single"))
    if not merged:
        lines += ["", "One training seed: `make paper`'s seed step (two more seeds for every "
                      "learned method) has not merged yet."]
    return "\n".join(lines)


def sim_size(metrics: dict) -> str:
    """How many trials the committed evaluation simulated."""
    methods = table_methods(metrics)
    pairs = sum(metrics[m].get("n_trials", 0) for m in methods)
    runs = sum(metrics[m].get("n_sim_runs", metrics[m].get("n_trials", 0)) for m in methods)
    proposing = [m for m in methods
                 if metrics[m].get("n_sim_runs", 0) > metrics[m].get("n_trials", 0)]
    text = (f"`sim_eval` simulated {runs} trials: {pairs} first trials ({len(methods)} methods, "
            "one per (support, object) pair each)")
    if proposing:
        names = ", ".join(f"`{m}`" for m in proposing)
        text += (f", and {runs - pairs} later proposals of {names} on pairs their earlier "
                 "proposals had not hung")
    return text + "."


def bench_table(bench: dict) -> str:
    """The committed bench.json as a table, one row per measured key."""
    sample = []
    if "machine" in bench:
        sample.append(f"on {bench['machine']}")
    if "rrt_bench_supports" in bench:
        sample.append(f"planning on {bench['rrt_bench_supports']} supports balanced across levels, "
                      f"{bench.get('rrt_bench_skts_per_support', '?')} SKTs asked of each "
                      f"({bench.get('rrt_bench_skts', '?')} planned by the one-tree planner, "
                      f"{bench.get('rrt_bench_skts_reference', '?')} by the reference)")
    if "sim_bench_trials" in bench:
        excluded = bench.get("sim_bench_setup_failures_excluded")
        sample.append(f"simulation over {bench['sim_bench_trials']} trials (the oracle's and "
                      f"SCTDN's SKTs; {bench.get('sim_bench_failures_reference', '?')} of them "
                      "failures" + ("" if excluded is None else
                                    f"; {excluded} more left out, whose set-up found no grasp")
                      + ")")
    if "parts_commit" in bench:
        sample.append("each part at its commit: " + ", ".join(
            f"{part} {commit}" for part, commit in bench["parts_commit"].items()))
    lines = (["Measured " + "; ".join(sample) + "; medians.", ""] if sample else [])
    lines += ["| key | value | what |", "|---|---|---|"]
    unknown = sorted(set(bench) - set(BENCH_ROWS) - set(BENCH_SAMPLE))
    for key in [k for k in BENCH_ROWS if k in bench] + unknown:
        fmt, meaning = BENCH_ROWS.get(key, ("{}", ""))
        value = bench[key]
        text = (", ".join(f"{k} {'–' if v is None else f'{v:.1f}'}" for k, v in value.items())
                if isinstance(value, dict) else fmt.format(value))
        lines.append(f"| `{key}` | {text} | {meaning} |")
    for key, which in (("sim_verdict_disagreements", "the default executor"),
                       ("sim_verdict_disagreements_previous", "the previous executor")):
        if key in bench:
            differ = bench[key]
            lines += ["", f"Verdicts {which} and the reference disagree on: "
                      + ("; ".join(f"`{d}`" for d in differ) if differ else "none") + "."]
    if "import_dense_failed" in bench:
        failed = bench["import_dense_failed"]
        lines += ["", "Dense imports refused: " + ("; ".join(f"`{k}`: {v}" for k, v in
                                                         failed.items()) if failed else "none")
                  + "."]
    return "\n".join(lines)


def paper_preset(bench: dict) -> str:
    """The paper preset's planning time at the committed planning rate."""
    rate = bench.get("rrt_skts_per_min")
    if not rate:
        return "No planning rate in `reports/bench/bench.json`: run `make bench`."
    return (f"≈ {PAPER_SKTS / rate / 60:.1f} h for its {PAPER_SKTS:,} SKTs at {rate:.0f} SKTs per "
            "minute (the committed `rrt_skts_per_min`, on `compute.n_workers` workers).")


def blocks(reports: dict) -> dict[str, dict[str, str]]:
    """File (relative to the repo root) -> block name -> the block's generated text."""
    metrics, bench, paper = reports["metrics"], reports["bench"], reports.get("paper") or {}
    data = reports.get("scaling", {})
    return {
        "README.md": {"results": paper_table_one(paper, metrics) if paper else table_one(metrics),
                      "presets": scaling.presets_summary(data)},
        "docs/presets.md": {"default-results": table_one(metrics),
                            "sim-size": sim_size(metrics), "bench": bench_table(bench),
                            "paper-preset": paper_preset(bench),
                            "paper-run": scaling.paper_table(data),
                            "fresh-repro": scaling.fresh_summary(data),
                            "scaling": scaling.table(data)},
    }


def _markers(name: str) -> tuple[str, str]:
    return f"<!-- {name}:start -->", f"<!-- {name}:end -->"


def read_block(text: str, name: str, where: str = "text") -> str:
    """The text between the markers of block ``name`` (without the newlines by the markers)."""
    start, end = _markers(name)
    if text.count(start) != 1 or text.count(end) != 1:
        raise DocsError(f"{where}: needs exactly one '{start}' and one '{end}'")
    i, j = text.index(start) + len(start), text.index(end)
    if j < i:
        raise DocsError(f"{where}: '{end}' comes before '{start}'")
    return text[i:j].strip("\n")


def write_block(text: str, name: str, body: str, where: str = "text") -> str:
    """``text`` with block ``name`` replaced by ``body``."""
    read_block(text, name, where)
    start, end = _markers(name)
    head, rest = text.split(start, 1)
    return f"{head}{start}\n{body}\n{end}{rest.split(end, 1)[1]}"


def render(root: Path = ROOT, reports: dict | None = None) -> dict[str, tuple[str, str]]:
    """File -> (current text, text with every block regenerated)."""
    reports = load_reports(root) if reports is None else reports
    out = {}
    for rel, named in blocks(reports).items():
        path = root / rel
        if not path.is_file():
            raise DocsError(f"{rel}: not found")
        old = new = path.read_text()
        for name, body in named.items():
            new = write_block(new, name, body, rel)
        out[rel] = (old, new)
    return out


def stale(root: Path = ROOT) -> list[str]:
    """A unified diff per file whose blocks differ from what would be written; empty if none."""
    diffs = []
    for rel, (old, new) in render(root).items():
        if old != new:
            diffs.append("".join(difflib.unified_diff(
                old.splitlines(keepends=True), new.splitlines(keepends=True),
                f"{rel} (committed)", f"{rel} (from the reports)")))
    return diffs


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="tools.docs_results", description=__doc__.splitlines()[0])
    ap.add_argument("--check", action="store_true",
                    help="write nothing; exit 1 with a diff if a block is out of date")
    ap.add_argument("--root", type=Path, default=ROOT,
                    help="repository root (default: this checkout)")
    args = ap.parse_args(argv)
    try:
        if args.check:
            diffs = stale(args.root)
            for diff in diffs:
                print(diff, end="")
            if diffs:
                print("ERROR: run figures in the docs are out of date: run "
                      "`.venv/bin/python -m tools.docs_results`", file=sys.stderr)
            return 1 if diffs else 0
        for rel, (old, new) in render(args.root).items():
            if old != new:
                tmp = (args.root / rel).with_suffix(".md.tmp")
                tmp.write_text(new)
                tmp.replace(args.root / rel)
                print(f"{rel}: run figures rewritten from the reports")
    except DocsError as err:
        print(f"ERROR: {err}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
