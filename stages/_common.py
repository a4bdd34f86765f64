"""Boilerplate every stage shares: arguments, logging, progress bars, failure counting."""

import argparse
import functools
import logging
import os
import sys
from collections import Counter
from collections.abc import Callable, Sequence

from tqdm import tqdm

from skt_lib.config import ComputeParams
from skt_lib.errors import SktError
from skt_lib.parallel import Failed, capture, map_items
from skt_lib.resume import ItemStore

log = logging.getLogger("resume")


def parse_args(stage: str, argv: Sequence[str] | None) -> argparse.Namespace:
    ap = argparse.ArgumentParser(prog=f"stages.{stage}", description=f"Run the {stage} stage.")
    ap.add_argument("--params", default="params.yaml", help="params file (default: params.yaml)")
    ap.add_argument("--data-dir", default=f"data/{stage}", help="artifact directory")
    ap.add_argument("--reports-dir", default=f"reports/{stage}", help="report directory")
    ap.add_argument("--data-root", default="data", help="where earlier stages' artifacts live")
    ap.add_argument("--log-dir", default="logs",
                    help="run log: wall-clock figures, not tracked by git or DVC (default: logs)")
    args = ap.parse_args(argv)
    args.stage = stage
    logging.basicConfig(level=logging.INFO, format=f"[{stage}] %(levelname)s %(message)s")
    sys.excepthook = _report_skt_error
    return args


def _report_skt_error(exc_type, exc, tb) -> None:
    """Uncaught :class:`SktError` (bad params, a broken artifact…) in ``python -m stages.X``:
    its message only, no traceback (``SKT_DEBUG=1`` shows it); anything else is a bug and
    keeps its traceback. The exit code stays 1."""
    if issubclass(exc_type, SktError) and not os.environ.get("SKT_DEBUG"):
        sys.stderr.write(f"ERROR: {exc}\n")
    else:
        sys.__excepthook__(exc_type, exc, tb)


def item_store(args: argparse.Namespace) -> ItemStore:
    """Where this stage run keeps finished items (resumable stages, skt_lib.resume)."""
    return ItemStore.for_stage(args.stage, args.params, args.data_root, args.data_dir)


def run_items(fn: Callable, items: list, compute: ComputeParams, desc: str,
              work: ItemStore | None = None):
    """Run ``fn`` over items with a progress bar; returns (ok values, Counter of failure
    reasons, list of (item, Failed)).

    With ``work``, items finished by an earlier, interrupted run of the same stage on the same
    inputs are read back instead of recomputed, and each newly finished item is saved as it
    completes. Crashes (bugs) are not saved."""
    task = functools.partial(capture, fn)
    results: list = [ItemStore.MISSING] * len(items)
    keys = [ItemStore.key(fn, it) for it in items] if work else []
    if work:
        results = [work.load(k) for k in keys]
    todo = [i for i, r in enumerate(results) if r is ItemStore.MISSING]
    if work and len(todo) < len(items):
        log.info("resuming: %d of %d items already done in %s", len(items) - len(todo),
                 len(items), work.folder)

    def done(j: int, result) -> None:
        results[todo[j]] = result
        if work:
            work.save(keys[todo[j]], result)
        bar.update()

    with tqdm(total=len(items), initial=len(items) - len(todo), desc=desc, unit="item",
              dynamic_ncols=True) as bar:
        map_items(task, [items[i] for i in todo], compute, on_done=done)
    ok = [r for r in results if not isinstance(r, Failed)]
    failed = [(it, r) for it, r in zip(items, results) if isinstance(r, Failed)]
    return ok, Counter(f.reason for _, f in failed), failed
