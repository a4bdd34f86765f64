"""Imported items in the evaluation (``sim_eval.extra_supports`` / ``extra_objects``): every
method on every pair that has at least one imported item — an imported support with every
test object and imported object, and every generated test support with each imported
object — as rows apart from Table I's, which they never enter.

Imported items live in ``<data-root>/user/`` (``skt import-support`` / ``skt import-object``);
DVC does not track that folder, so the metrics name each item's record and its md5: a
changed import shows in ``dvc metrics diff``.
"""

import hashlib
from collections.abc import Callable
from pathlib import Path

import pandas as pd

from skt_lib.errors import InputError
from skt_lib.eval.methods import PRIVILEGED
from skt_lib.eval.rounds import run_rounds
from skt_lib.items import (
    OBJECT_RECORD,
    SUPPORT_RECORD,
    TestObject,
    TestSupport,
    find_object,
    find_support,
    user_dir,
)


def load_user_items(root: Path, params) -> tuple[list[TestSupport], list[TestObject], dict]:
    """(imported supports, imported objects, {name: md5 of its record}) named in params."""
    p = params.sim_eval
    for kind, names in (("support", p.extra_supports), ("object", p.extra_objects)):
        for name in names:
            if not user_dir(root, kind, name).is_dir():
                raise InputError(f"sim_eval.extra_{kind}s: {name!r} is not imported "
                                 f"({user_dir(root, kind, name)} missing; use skt import-{kind})")
    privileged = [m for m in p.methods if m in PRIVILEGED]
    need = f"sim_eval.methods {privileged} need one" if privileged else None
    supports = [find_support(n, root, params, gt_for=need) for n in p.extra_supports]
    objects = [find_object(n, root, params) for n in p.extra_objects]
    md5 = {f"{kind}/{n}": hashlib.md5((user_dir(root, kind, n) / rec).read_bytes()).hexdigest()
           for kind, names, rec in (("support", p.extra_supports, SUPPORT_RECORD),
                                    ("object", p.extra_objects, OBJECT_RECORD)) for n in names}
    return supports, objects, md5


def run_user_trials(methods, supports, objects, extra_s, extra_o, positions: dict, settings,
                    run: Callable, fallbacks: dict | None = None) -> list[dict]:
    """Trial rows of every pair with an imported item, the proposals' rounds included
    (:func:`~skt_lib.eval.rounds.run_rounds`); ``positions`` (and ``fallbacks``) must hold
    every support's."""
    rows = []
    if extra_s:
        rows += run_rounds(methods, extra_s, [*objects, *extra_o], positions, settings, run,
                           fallbacks)[0]
    if extra_o and supports:
        rows += run_rounds(methods, supports, extra_o, positions, settings, run, fallbacks)[0]
    return rows


def user_metrics(rows: list[dict], methods, md5: dict) -> dict:
    """Per method: pairs, pairs hung (any proposal), success rate; and the records' md5."""
    out = {"records_md5": md5}
    if not rows:
        return out
    t = pd.DataFrame(rows)
    pairs = t.groupby(["method", "support_id", "object_id"])["success"].any().reset_index()
    for m in methods:
        g = pairs[pairs["method"] == m]
        out[m] = {"n_pairs": len(g), "n_success": int(g["success"].sum()),
                  "success": float(g["success"].mean()) if len(g) else None}
    return out


def user_table(metrics: dict, methods) -> list[list]:
    """Rows (method, pairs, hung, rate %) for the report."""
    return [[f"`{m}`", metrics[m]["n_pairs"], metrics[m]["n_success"],
             "–" if metrics[m]["success"] is None else f"{100 * metrics[m]['success']:.1f}"]
            for m in methods if m in metrics]
