"""Table I over training seeds: the key that says what extra seeds were made from, the merge
of their per-pair outcomes with this run's, and its report section."""

import json

import numpy as np
import pandas as pd
import pytest
import yaml

from skt_lib.errors import DataError
from skt_lib.eval.seeds import inputs_key, models_key, runs_document, seed_block
from viz.report import Report
from viz.sim_eval_report import _seeds_section

LEVELS = ["easy"] * 4 + ["very_hard"] * 4
BASE = 7


def _repo(tmp_path):
    repo = tmp_path / "repo"
    for path, text in {"params.yaml": "common: {seed: 7}\n",
                       "skt_lib/sim/execute.py": "A = 1\n", "stages/sim_eval.py": "run()\n",
                       "viz/report.py": "pretty()\n", "skt_lib/eval/metrics.py": "table()\n",
                       "skt_lib/eval/methods.py": "sctdn()\n", "skt_lib/eval/seeds.py": "merge()\n",
                       "data/views/v.npz": "cloud"}.items():
        (repo / path).parent.mkdir(parents=True, exist_ok=True)
        (repo / path).write_text(text)
    (repo / "dvc.yaml").write_text(yaml.safe_dump({"stages": {"sim_eval": {"deps": [
        "stages/sim_eval.py", "skt_lib/sim", "viz/report.py", "skt_lib/eval",
        "data/views", "reports/seeds/seed_runs.json"]}}}))
    _lock(repo, views="v1", train_outs="m1", train_deps="c1", sim_eval="e1")
    return repo


def _lock(repo, views, train_outs, train_deps, sim_eval):
    (repo / "dvc.lock").write_text(yaml.safe_dump({"schema": "2.0", "stages": {
        "render_views": {"outs": [{"path": "data/views", "md5": views}]},
        "train": {"deps": [{"path": "skt_lib/learning", "md5": train_deps}],
                  "outs": [{"path": "data/train", "md5": train_outs}]},
        "sim_eval": {"outs": [{"path": "data/sim_eval", "md5": sim_eval}]}}}))


def test_the_key_follows_data_code_and_params_but_not_models_reports_or_its_own_entry(tmp_path):
    repo = _repo(tmp_path)
    key = inputs_key(repo)
    _lock(repo, views="v1", train_outs="m2", train_deps="c1", sim_eval="e2")
    (repo / "viz/report.py").write_text("prettier()\n")
    (repo / "skt_lib/eval/metrics.py").write_text("wider_table()\n")  # in a directory dep
    (repo / "skt_lib/eval/seeds.py").write_text("merge_better()\n")
    (repo / "data/views/v.npz").write_text("another cloud")  # read through the lock only
    assert inputs_key(repo) == key  # the base seed's models, sim_eval's stale entry, reports

    changes = [lambda: _lock(repo, views="v2", train_outs="m2", train_deps="c1", sim_eval="e2"),
               lambda: _lock(repo, views="v2", train_outs="m2", train_deps="c2", sim_eval="e2"),
               lambda: (repo / "skt_lib/sim/new.py").write_text("B = 2\n"),
               lambda: (repo / "stages/sim_eval.py").write_text("run(faster=True)\n"),
               lambda: (repo / "skt_lib/eval/methods.py").write_text("sctdn(v=2)\n"),
               lambda: (repo / "params.yaml").write_text("common: {seed: 8}\n")]
    seen = {key}
    for change in changes:  # data, training code, trial code (a file added), the stage,
        # trial code beside reporting code in one directory, params
        change()
        seen.add(inputs_key(repo))
    assert len(seen) == len(changes) + 1


def test_the_models_key_follows_training_inputs_only(tmp_path):
    repo = _repo(tmp_path)
    _lock(repo, views="v1", train_outs="m1", train_deps="c1", sim_eval="e1")
    key = models_key(repo)
    _lock(repo, views="v2", train_outs="m2", train_deps="c1", sim_eval="e2")
    (repo / "params.yaml").write_text("sim_eval: {n_record: 0}\n")
    (repo / "stages/sim_eval.py").write_text("run(faster=True)\n")
    assert models_key(repo) == key  # upstream entries, its own outputs, sim_eval: not training's
    _lock(repo, views="v2", train_outs="m2", train_deps="c2", sim_eval="e2")
    assert models_key(repo) != key  # training's code (or data, or params) changed


def _pairs(flags: dict[str, list[int]]) -> pd.DataFrame:
    rows = [{"method": m, "support_id": f"s{i // 2}", "object_id": f"o{i % 2}",
             "difficulty": lv, "success": bool(v), "failure_reason": ""}
            for m, ok in flags.items() for i, (v, lv) in enumerate(zip(ok, LEVELS))]
    return pd.DataFrame(rows)


BASE_RUN = {"oracle": [1] * 8,
            "sctdn": [1, 1, 1, 0, 1, 0, 0, 0], "template_only": [1, 0, 0, 0, 0, 0, 0, 0],
            "vatmart": [1, 1, 0, 0, 1, 1, 0, 0], "vatmart@1": [1, 0, 0, 0, 1, 0, 0, 0]}
SEED_8 = {"sctdn": [1, 1, 1, 1, 1, 1, 0, 0], "template_only": [1, 1, 0, 0, 0, 0, 0, 0],
          "vatmart": [0, 0, 0, 0, 1, 1, 1, 1], "vatmart@1": [0, 0, 0, 0, 1, 1, 0, 0]}
SEED_9 = {"sctdn": [1, 1, 0, 0, 1, 1, 1, 1], "template_only": [1, 1, 1, 0, 1, 0, 0, 0],
          "vatmart": [1, 1, 1, 1, 0, 0, 0, 0], "vatmart@1": [1, 1, 0, 0, 0, 0, 0, 0]}


def _write_runs(repo, runs: dict[int, dict], key=None):
    path = repo / "reports/seeds/seed_runs.json"
    path.parent.mkdir(parents=True, exist_ok=True)
    doc = runs_document(key or inputs_key(repo), {s: _pairs(r) for s, r in runs.items()})
    path.write_text(json.dumps(doc))
    return path


def test_seeds_merge_into_mean_min_max_per_level_and_orderings_over_seeds(tmp_path):
    repo = _repo(tmp_path)
    path = _write_runs(repo, {8: SEED_8, 9: SEED_9})
    got = seed_block(_pairs(BASE_RUN), BASE, path, repo)
    assert got["status"] == "ok" and got["seeds"] == [7, 8, 9]
    assert "oracle" not in got  # no training seed: not in the table
    s = got["sctdn"]
    assert s["success_per_seed"]["8"] == {"all": 0.75, "easy": 1.0, "normal": None,
                                          "hard": None, "very_hard": 0.5}
    assert s["success_mean"]["easy"] == pytest.approx((0.75 + 1.0 + 0.5) / 3)
    assert (s["success_min"]["very_hard"], s["success_max"]["very_hard"]) == (0.25, 1.0)
    assert s["success_mean"]["all"] == pytest.approx((0.5 + 0.75 + 0.75) / 3)
    assert s["success_mean"]["normal"] is None
    v = got["vatmart"]  # best-of-N and the first proposal, each over the seeds
    assert v["success_mean"]["all"] == pytest.approx(0.5)
    assert v["success_single_min"]["easy"] == 0.0 and v["success_single_max"]["easy"] == 0.5

    checks = {c["claim"]: c for c in got["paper_orderings"]}
    c = checks["sctdn ≥ template_only + 10 points (all levels)"]
    assert c["rate_a_mean"] == pytest.approx(2 / 3) and c["rate_b_mean"] == pytest.approx(7 / 24)
    assert c["holds"] and c["holds_on_seeds"] == 3
    assert [c["per_seed"][s]["n_a_only"] for s in ("7", "8", "9")] == [3, 4, 3]
    lo, hi = c["diff_ci95"]
    assert lo <= c["diff_mean"] <= hi and 0 < lo  # sctdn ahead on every support
    assert not any("vatmart_mod" in k for k in checks)  # it did not run


def test_seeds_are_not_merged_from_other_inputs_or_other_pairs(tmp_path):
    repo = _repo(tmp_path)
    path = repo / "reports/seeds/seed_runs.json"
    assert seed_block(_pairs(BASE_RUN), BASE, path, repo)["status"] == "missing"

    _write_runs(repo, {8: SEED_8}, key="0" * 64)
    got = seed_block(_pairs(BASE_RUN), BASE, path, repo)
    assert got["status"] == "stale" and "sctdn" not in got and "make seeds" in got["reason"]

    _write_runs(repo, {8: SEED_8})
    (repo / "params.yaml").write_text("common: {seed: 7}\nsim_eval: {n_proposals: 3}\n")
    assert seed_block(_pairs(BASE_RUN), BASE, path, repo)["status"] == "stale"

    _write_runs(repo, {8: SEED_8})
    fewer = _pairs(BASE_RUN)
    fewer = fewer[fewer["support_id"] != "s3"]  # this run evaluated other pairs
    assert seed_block(fewer, BASE, path, repo)["status"] == "stale"
    assert seed_block(_pairs(BASE_RUN), BASE, path, repo)["status"] == "ok"

    _write_runs(repo, {7: SEED_8})  # the committed seed cannot be an extra one
    with pytest.raises(DataError, match="common.seed 7"):
        seed_block(_pairs(BASE_RUN), BASE, path, repo)


def test_a_malformed_seed_runs_file_is_a_clear_error(tmp_path):
    repo = _repo(tmp_path)
    path = _write_runs(repo, {8: SEED_8})
    doc = json.loads(path.read_text())
    doc["seeds"]["8"]["sctdn"] = doc["seeds"]["8"]["sctdn"][:-1]
    path.write_text(json.dumps(doc))
    with pytest.raises(DataError, match="seed_runs.json.*8/sctdn"):
        seed_block(_pairs(BASE_RUN), BASE, path, repo)
    path.write_text(json.dumps({**doc, "format": "v0"}))
    with pytest.raises(DataError, match="format 'v0'"):
        seed_block(_pairs(BASE_RUN), BASE, path, repo)
    with pytest.raises(ValueError, match="not the same"):
        runs_document("k", {8: _pairs(SEED_8), 9: _pairs(SEED_8).iloc[2:]})


def test_the_report_shows_mean_and_range_and_says_why_when_not_merged(tmp_path):
    repo = _repo(tmp_path)
    path = _write_runs(repo, {8: SEED_8, 9: SEED_9})
    report = Report("sim_eval", tmp_path / "rep")
    _seeds_section(report, seed_block(_pairs(BASE_RUN), BASE, path, repo))
    _seeds_section(report, {"status": "stale", "reason": "made from other inputs"})
    report.write()
    text = (tmp_path / "rep" / "report.md").read_text()
    assert "| sctdn | 66.7 [50.0–75.0] | 75.0 [50.0–100.0] | – | – | 58.3 [25.0–100.0] |" in text
    assert "Training seeds 7, 8, 9" in text
    assert "Not merged: made from other inputs." in text
    assert np.isfinite(json.loads(path.read_text())["seeds"]["8"]["sctdn"]).all()
