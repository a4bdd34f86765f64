"""Table I over three training seeds: the learned methods' per-pair outcomes under the extra
training seeds (``reports/seeds/seed_runs.json``, written by ``make seeds``), merged by
``sim_eval`` with its own run (``common.seed``) into ``metrics["seeds"]``.

An extra seed's outcomes are only as good as the inputs they were made from, so the file
carries :func:`inputs_key` and ``sim_eval`` merges it only when the key equals the current
one and the (support, object) pairs are the ones it just ran; otherwise ``metrics["seeds"]``
says ``stale`` (or ``missing``) and carries no rates.

``seed_runs.json`` (format ``skt-hang seed runs v1``)::

    {"format": "skt-hang seed runs v1", "inputs_key": "<sha256 hex>",
     "pairs": [[support_id, object_id], ...],
     "seeds": {"<seed>": {"<method>": [0 | 1 per pair, in "pairs" order], ...}, ...}}

``<method>`` includes the proposing methods' single-proposal rows (``vatmart@1``).
"""

import hashlib
import json
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

from skt_lib.config import LEVELS
from skt_lib.errors import DataError
from skt_lib.eval.methods import LEARNED, PROPOSING
from skt_lib.eval.orderings import PAPER_ORDERINGS, check_orderings
from skt_lib.eval.protocol import SINGLE, success_table
from skt_lib.seeding import item_rng
from skt_lib.stats import bootstrap_mean_interval

FORMAT = "skt-hang seed runs v1"
#: The methods a training seed changes.
SEEDED = (*LEARNED, *PROPOSING)
#: Stages whose outputs are the models of one training seed: their lock entries' outputs are
#: left out of the key (an extra seed trains its own).
MODEL_STAGES = ("train", "train_baselines")
#: sim_eval's code dependencies that only turn trials into reports and recordings; a change
#: to them cannot change a trial's outcome, so they are left out of the key.
REPORTING_ONLY = ("viz/", "skt_lib/eval/metrics.py", "skt_lib/eval/orderings.py",
                  "skt_lib/stats.py", "skt_lib/eval/seeds.py")
KEYS = ("all", *LEVELS)


def inputs_key(repo: Path) -> str:
    """sha256 of what an extra training seed's ``sim_eval`` outcomes depend on, in the
    repository ``repo``: ``params.yaml``; every ``dvc.lock`` stage but ``sim_eval`` (for
    :data:`MODEL_STAGES` without their outputs); and the contents of ``sim_eval``'s code
    dependencies in ``dvc.yaml`` (outside ``data/`` and ``reports/``, less
    :data:`REPORTING_ONLY`), read from disk — ``sim_eval``'s own lock entry is stale while
    it runs."""
    h = hashlib.sha256((repo / "params.yaml").read_bytes())
    lock_path = repo / "dvc.lock"
    stages = yaml.safe_load(lock_path.read_text())["stages"] if lock_path.is_file() else {}
    for name in sorted(stages):
        if name == "sim_eval":
            continue
        entry = {k: v for k, v in stages[name].items()
                 if not (name in MODEL_STAGES and k == "outs")}
        h.update(json.dumps([name, entry], sort_keys=True).encode())
    dvc_yaml = repo / "dvc.yaml"
    deps = yaml.safe_load(dvc_yaml.read_text())["stages"]["sim_eval"]["deps"] \
        if dvc_yaml.is_file() else []
    for dep in sorted(deps):
        if dep.startswith(("data/", "reports/")):
            continue
        path = repo / dep
        files = sorted(p for p in path.rglob("*") if p.is_file() and "__pycache__" not in p.parts) \
            if path.is_dir() else [path]
        for f in files:  # per file: a directory dependency holds reporting modules too
            rel = f.relative_to(repo).as_posix()
            if not rel.startswith(REPORTING_ONLY):
                h.update(rel.encode() + b"\0" + f.read_bytes())
    return h.hexdigest()


def models_key(repo: Path) -> str:
    """sha256 of what an extra training seed's *models* depend on, in ``repo``: the
    ``dvc.lock`` entries of :data:`MODEL_STAGES` without their outputs (their data and code
    dependencies' hashes and their params), less their figure code (``viz/``). A change that leaves training alone — to ``sim_eval``, its
    params, or an upstream stage's code that writes the same bytes — keeps it, so a seed's
    models outlive it and only its trials run again."""
    lock_path = repo / "dvc.lock"
    stages = yaml.safe_load(lock_path.read_text())["stages"] if lock_path.is_file() else {}
    h = hashlib.sha256()
    for name in MODEL_STAGES:
        entry = {k: v for k, v in stages.get(name, {}).items() if k != "outs"}
        entry["deps"] = [d for d in entry.get("deps", [])
                         if not d.get("path", "").startswith("viz/")]
        h.update(json.dumps([name, entry], sort_keys=True).encode())
    return h.hexdigest()


def runs_document(key: str, pairs_by_seed: dict[int, pd.DataFrame]) -> dict:
    """The ``seed_runs.json`` document of extra seeds' per-pair outcomes (each a
    :func:`~skt_lib.eval.protocol.per_pair` table of one seed's ``sim_eval``; every seed
    must have the same pairs)."""
    if not pairs_by_seed:
        raise ValueError("pairs_by_seed: no seeds")
    order = None
    seeds = {}
    for seed, pairs in pairs_by_seed.items():
        ids = _pair_ids(pairs)
        if order is None:
            order = ids
        elif ids != order:
            raise ValueError(f"seed {seed}: not the same (support, object) pairs as the first seed")
        seeds[str(seed)] = {m: [int(v) for v in _flags(pairs, m, order)]
                            for m in dict.fromkeys(pairs["method"]) if _base(m) in SEEDED}
    return {"format": FORMAT, "inputs_key": key, "pairs": [list(p) for p in order],
            "seeds": seeds}


def seed_block(pairs: pd.DataFrame, base_seed: int, runs_path: Path, repo: Path) -> dict:
    """``metrics["seeds"]``: this run's pairs (``common.seed``) with the extra seeds of
    ``runs_path``, merged when its key is :func:`inputs_key` of ``repo``. Per learned method
    present in both, ``success_mean`` / ``success_min`` / ``success_max`` /
    ``success_per_seed`` per level and ``all`` (proposing methods also the
    same for their first proposal, ``success_single_*``), and ``paper_orderings`` judged on
    the mean over seeds with each seed's McNemar test and a bootstrap-over-supports interval
    of the mean difference. ``{"status": "missing" | "stale", "reason"}`` when the file
    cannot be merged."""
    name = f"{runs_path.parent.name}/{runs_path.name}"  # metrics carry no machine's paths
    if not runs_path.is_file():
        return {"status": "missing", "reason": f"no {name}; run `make seeds`"}
    try:
        doc = json.loads(runs_path.read_text())
        if doc.get("format") != FORMAT:
            raise DataError(f"format {doc.get('format')!r}, expected {FORMAT!r}")
        extra = {int(s): runs for s, runs in doc["seeds"].items()}
        listed = [tuple(p) for p in doc["pairs"]]
        bad = [f"{s}/{m}" for s, runs in extra.items() for m, v in runs.items()
               if len(v) != len(listed) or not set(v) <= {0, 1}]
        if bad:
            raise DataError(f"outcomes {bad[:3]} are not one 0/1 per listed pair")
        key = doc["inputs_key"]
    except (ValueError, KeyError, TypeError, AttributeError) as e:
        raise DataError(f"{runs_path}: not a seed runs file: {e}") from e
    if key != inputs_key(repo):
        return {"status": "stale", "reason": f"{name} was made from other inputs (data, "
                "code or params); run `make seeds`"}
    methods = [m for m in dict.fromkeys(pairs["method"]) if _base(m) in SEEDED
               and all(m in runs for runs in extra.values())]
    if not methods or any(set(_pair_ids(pairs[pairs["method"] == m])) != set(listed)
                          for m in methods):
        return {"status": "stale", "reason": f"{name}: other (support, object) pairs or "
                "methods than this run's; run `make seeds`"}
    if base_seed in extra:
        raise DataError(f"{runs_path}: holds common.seed {base_seed}, which this run trains")
    by_seed = {base_seed: pairs[pairs["method"].isin(methods)].reset_index(drop=True)}
    for seed, runs in sorted(extra.items()):
        by_seed[seed] = _seed_pairs(by_seed[base_seed], listed, runs, methods)
    out = {"status": "ok", "seeds": list(by_seed)}
    tables = {s: success_table(p) for s, p in by_seed.items()}
    for m in methods:
        field = "success_single" if m.endswith(SINGLE) else "success"
        block = out.setdefault(_base(m), {})
        per_seed = {str(s): tables[s][m] for s in by_seed}
        block[f"{field}_per_seed"] = per_seed
        for stat, fn in (("mean", np.mean), ("min", np.min), ("max", np.max)):
            block[f"{field}_{stat}"] = {
                lv: (None if any(r[lv] is None for r in per_seed.values())
                     else float(fn([r[lv] for r in per_seed.values()]))) for lv in KEYS}
    out["paper_orderings"] = orderings_over_seeds(by_seed, base_seed)
    return out


def orderings_over_seeds(by_seed: dict[int, pd.DataFrame], seed: int,
                         orderings=PAPER_ORDERINGS) -> list[dict]:
    """Each paper ordering whose methods ran: the mean rates over seeds and whether it holds
    on them, each seed's check (rates, discordant pairs, McNemar p), and the 95 % interval
    of the mean difference A − B under a bootstrap over test supports (a support's pairs
    are drawn together, with every seed's outcome on them)."""
    per_seed = {s: {c["claim"]: c for c in check_orderings(p, orderings)} for s, p in
                by_seed.items()}
    out = []
    for claim, a, b, level, margin, strict in orderings:
        if not all(claim in checks for checks in per_seed.values()):
            continue
        checks = {s: per_seed[s][claim] for s in by_seed}
        ra = float(np.mean([c["rate_a"] for c in checks.values()]))
        rb = float(np.mean([c["rate_b"] for c in checks.values()]))
        gap = ra - rb - margin
        diffs = []
        for p in by_seed.values():
            sub = p if level == "all" else p[p["difficulty"] == level]
            fa, fb = (sub[sub["method"] == m].set_index(["support_id", "object_id"])["success"]
                      .astype(float) for m in (a, b))
            diffs.append((fa - fb).sort_index())
        mean_diff = pd.concat(diffs, axis=1).mean(axis=1)
        groups = mean_diff.index.get_level_values("support_id")
        ci = bootstrap_mean_interval(mean_diff.to_numpy(), np.asarray(groups),
                                     item_rng(seed, "sim_eval/seeds", claim))
        out.append({"claim": claim, "a": a, "b": b, "level": level, "rate_a_mean": ra,
                    "rate_b_mean": rb, "holds": bool(gap > 1e-12 if strict else gap >= -1e-12),
                    "holds_on_seeds": int(sum(c["holds"] for c in checks.values())),
                    "diff_mean": ra - rb, "diff_ci95": None if ci is None else list(ci),
                    "per_seed": {str(s): {k: c[k] for k in ("rate_a", "rate_b", "n_a_only",
                                                             "n_b_only", "p_value")}
                                 for s, c in checks.items()}})
    return out


def _seed_pairs(base: pd.DataFrame, listed: list[tuple], runs: dict, methods) -> pd.DataFrame:
    """``base`` (this run's pairs of ``methods``) with the success flags of another seed."""
    rows = []
    for m in methods:
        flags = pd.Series(np.asarray(runs[m], bool), index=pd.MultiIndex.from_tuples(listed))
        g = base[base["method"] == m].copy()
        g["success"] = flags.loc[list(map(tuple, g[["support_id", "object_id"]].to_numpy()))] \
            .to_numpy()
        rows.append(g)
    return pd.concat(rows, ignore_index=True)


def _pair_ids(pairs: pd.DataFrame) -> list[tuple]:
    return list(dict.fromkeys(map(tuple, pairs[["support_id", "object_id"]].to_numpy().tolist())))


def _flags(pairs: pd.DataFrame, method: str, order: list[tuple]) -> np.ndarray:
    g = pairs[pairs["method"] == method].set_index(["support_id", "object_id"])["success"]
    return g.loc[order].to_numpy(bool)


def _base(method: str) -> str:
    return method.removesuffix(SINGLE)
