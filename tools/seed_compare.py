"""Two rows of Table I compared over training seeds (``make seeds`` runs it): the default
predictor's one SKT against the best single-row rival by default, on every level.

The pairs are ``sim_eval``'s (``<root>/data/sim_eval/trials.parquet``, ``common.seed``) and the
extra seeds' outcomes on the same pairs (``<root>/reports/seeds/seed_runs.json``), merged only
when its inputs key is current, as ``sim_eval`` merges them. Per level: the mean rates over
seeds, each seed's exact McNemar test, and the 95 % interval of the mean difference A − B from
a bootstrap over test supports (a support's pairs drawn together, with every seed's outcome
on them) — the same statistics as Table I's orderings over seeds. Writes ``--out`` (JSON) and
prints a Markdown table; nothing else changes.

    python -m tools.seed_compare                       # the default workspace
    python -m tools.seed_compare --root paper --out reports/paper/seeds/compare.json
"""

import argparse
import json
import sys
from pathlib import Path

import pandas as pd

from skt_lib.config import LEVELS
from skt_lib.config.params_file import load_params
from skt_lib.errors import DataError
from skt_lib.eval.protocol import per_pair
from skt_lib.eval.seeds import _seed_pairs, orderings_over_seeds, seed_block
from skt_lib.io import read_table, write_json_atomic
from skt_lib.schemas import TRIALS

#: The default predictor's one-SKT row and the best-of-N row the issue measures it against.
DEFAULT_A, DEFAULT_B = "skt_flow@1", "vatmart_mod"


def seed_pairs(root: Path) -> dict[int, pd.DataFrame]:
    """``{training seed: per-pair outcomes}`` of ``root``'s ``sim_eval`` run and its extra
    seeds (:func:`merge_seeds`)."""
    pairs = per_pair(read_table(root / "data/sim_eval/trials.parquet", TRIALS))
    return merge_seeds(pairs, load_params(root / "params.yaml").common.seed,
                       root / "reports/seeds/seed_runs.json", root)


def merge_seeds(pairs: pd.DataFrame, base: int, runs: Path, repo: Path
                ) -> dict[int, pd.DataFrame]:
    """``pairs`` (the run of training seed ``base``) and, per extra seed of ``runs``, the same
    pairs with that seed's outcomes, for the methods both hold; :class:`DataError` when
    ``sim_eval`` would not merge them (missing, stale: :func:`seed_block` decides)."""
    block = seed_block(pairs, base, runs, repo)
    if block["status"] != "ok":
        raise DataError(f"{repo}: the extra seeds cannot be merged: {block['reason']}")
    doc = json.loads(runs.read_text())
    listed = [tuple(p) for p in doc["pairs"]]
    out = {base: pairs}
    for seed in block["seeds"][1:]:
        flags = doc["seeds"][str(seed)]
        out[seed] = _seed_pairs(pairs, listed, flags, flags)
    return out


def compare(by_seed: dict[int, pd.DataFrame], a: str, b: str, seed: int) -> list[dict]:
    """A > B on all levels pooled and on each level, as :func:`orderings_over_seeds`."""
    for s, p in by_seed.items():
        missing = {a, b} - set(p["method"])
        if missing:
            raise DataError(f"seed {s}: no outcomes of {sorted(missing)}")
    claims = [(f"{a} > {b} ({level})", a, b, level, 0.0, True) for level in ("all", *LEVELS)]
    return orderings_over_seeds(by_seed, seed, claims)


def compare_document(by_seed: dict[int, pd.DataFrame], a: str, b: str) -> dict:
    """What ``--out`` holds: the rows, the seeds and every level's comparison."""
    return {"a": a, "b": b, "seeds": list(by_seed),
            "comparisons": compare(by_seed, a, b, next(iter(by_seed)))}


def markdown(rows: list[dict]) -> str:
    lines = ["| level | A % mean | B % mean | A − B, points [support 95 %] | seeds where A > B "
             "| A only / B only per seed |", "|---|---|---|---|---|---|"]
    for r in rows:
        lo, hi = (100 * x for x in r["diff_ci95"]) if r["diff_ci95"] else (float("nan"),) * 2
        disc = ", ".join(f"{c['n_a_only']}/{c['n_b_only']}" for c in r["per_seed"].values())
        lines.append(f"| {r['level']} | {100 * r['rate_a_mean']:.1f} "
                     f"| {100 * r['rate_b_mean']:.1f} "
                     f"| {100 * r['diff_mean']:+.1f} [{lo:+.1f}, {hi:+.1f}] "
                     f"| {r['holds_on_seeds']} / {len(r['per_seed'])} | {disc} |")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="tools/seed_compare.py", description=__doc__.splitlines()[0])
    ap.add_argument("--root", default=Path("."), type=Path,
                    help="the workspace: the repository (default) or the paper run's (paper)")
    ap.add_argument("--a", default=DEFAULT_A, help=f"row A (default {DEFAULT_A})")
    ap.add_argument("--b", default=DEFAULT_B, help=f"row B (default {DEFAULT_B})")
    ap.add_argument("--out", default=Path("reports/seeds/compare.json"), type=Path)
    args = ap.parse_args(argv)
    try:
        doc = compare_document(seed_pairs(args.root), args.a, args.b)
    except (DataError, OSError) as err:
        print(f"ERROR: {err}", file=sys.stderr)
        return 2
    write_json_atomic(args.out, doc)
    print(markdown(doc["comparisons"]))
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
