"""Boilerplate every stage shares: arguments, logging, progress bars, failure counting."""

import argparse
import functools
import logging
from collections import Counter
from collections.abc import Callable, Sequence

from tqdm import tqdm

from skt_lib.config import ComputeParams
from skt_lib.parallel import Failed, capture, map_items


def parse_args(stage: str, argv: Sequence[str] | None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(prog=f"stages.{stage}", description=f"Run the {stage} stage.")
    ap.add_argument("--params", default="params.yaml", help="params file (default: params.yaml)")
    ap.add_argument("--data-dir", default=f"data/{stage}", help="artifact directory")
    ap.add_argument("--reports-dir", default=f"reports/{stage}", help="report directory")
    ap.add_argument("--data-root", default="data", help="where earlier stages' artifacts live")
    args = ap.parse_args(argv)
    logging.basicConfig(level=logging.INFO, format=f"[{stage}] %(levelname)s %(message)s")
    return args


def run_items(fn: Callable, items: list, compute: ComputeParams, desc: str):
    """Run ``fn`` over items with a progress bar; returns (ok values, Counter of failure
    reasons, list of (item, Failed))."""
    with tqdm(total=len(items), desc=desc, unit="item", dynamic_ncols=True) as bar:
        results = map_items(functools.partial(capture, fn), items, compute,
                            on_done=lambda _i: bar.update())
    ok = [r for r in results if not isinstance(r, Failed)]
    failed = [(it, r) for it, r in zip(items, results) if isinstance(r, Failed)]
    return ok, Counter(f.reason for _, f in failed), failed
