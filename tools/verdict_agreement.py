"""Compare two ``sim_eval`` runs verdict by verdict (``trials.parquet`` of each).

A verdict is a trial's failure reason, empty on success. Trials are matched by ``trial_id``;
a proposing method's later proposals run only where the earlier ones failed, so a changed
verdict can add or remove later trials: those are counted apart, not as disagreements.

    python -m tools.verdict_agreement OLD.parquet NEW.parquet [--json OUT]

To compare against a committed run: ``git show REV:dvc.lock`` names the md5 of its
``data/sim_eval`` (a directory in DVC's cache, ``.dvc/cache/files/md5/…``), whose
``trials.parquet`` is the old run.
"""

import argparse
import json
import sys

import pandas as pd


def agreement(old: pd.DataFrame, new: pd.DataFrame) -> dict:
    """Share of common trials with the same verdict, per method and overall, and the
    disagreeing trials with both verdicts and details."""
    key = ["trial_id", "method", "failure_reason", "detail"]
    both = old[key].merge(new[key], on=["trial_id", "method"], suffixes=("_old", "_new"))
    same = both["failure_reason_old"] == both["failure_reason_new"]
    differ = both[~same]
    return {
        "n_common": len(both),
        "agreement": float(same.mean()) if len(both) else None,
        "by_method": {m: float(g.mean()) for m, g in same.groupby(both["method"], sort=False)},
        "only_old": sorted(set(old["trial_id"]) - set(new["trial_id"])),
        "only_new": sorted(set(new["trial_id"]) - set(old["trial_id"])),
        "disagreements": [
            {"trial_id": r.trial_id, "old": r.failure_reason_old or "success",
             "new": r.failure_reason_new or "success", "old_detail": r.detail_old,
             "new_detail": r.detail_new} for r in differ.itertuples()],
    }


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="tools.verdict_agreement", description=__doc__.splitlines()[0])
    ap.add_argument("old")
    ap.add_argument("new")
    ap.add_argument("--json", help="write the full comparison here")
    args = ap.parse_args(argv)
    out = agreement(pd.read_parquet(args.old), pd.read_parquet(args.new))
    print(f"{out['n_common']} common trials, verdict agreement {out['agreement']:.4f}; "
          f"{len(out['only_old'])} only in old, {len(out['only_new'])} only in new")
    for m, a in out["by_method"].items():
        print(f"  {m}: {a:.4f}")
    for d in out["disagreements"]:
        print(f"  {d['trial_id']}: {d['old']} → {d['new']}  ({d['old_detail']} | {d['new_detail']})")
    if args.json:
        with open(args.json, "w") as f:
            json.dump(out, f, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
