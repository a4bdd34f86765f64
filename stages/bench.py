"""bench — speed figures as JSON (``make bench``), kept apart from the tests.

Runs on the artifacts of ``make repro`` with the committed params and writes
``reports/bench/bench.json`` afresh (every key from this run; nothing kept from an older file):

- ``rrt_plan_s_median`` / ``rrt_recheck_s_median``: per SKT attempt / re-check, and
  ``rrt_skts_per_min`` on ``compute.n_workers`` workers, at ``--rrt-skts`` SKTs per support
  over supports balanced across levels (the hardest first, as ``rrt_skts`` orders its longest
  items); the same for the per-SKT reference planner (``*_reference``) in the same run,
  ``rrt_speedup_vs_reference_planner`` the ratio, and ``rrt_diversity_mm*`` the mean
  pairwise distance of a support's SKTs, per level;
- ``render_ms_per_view_median``: ray casting of one 320×240 view (Open3D), and
  ``render_total_ms_per_view_median``: the whole view (ray casting, FPS to N, shuffle,
  NPZ write share), over the same sample of supports, one process;
- ``sctdn_inference_ms_median``: SCTDN, batch 1, points in → SKT out, model loaded;
- ``skt_flow_inference_ms_median``: skt_flow, batch 1, points in → ``sim_eval.flow_samples``
  samples moved clear of the points, ordered by the training objects (the first: the SKT it
  executes), models loaded; ``skt_flow_{sample,clear,order}_ms_median``: each step apart;
- ``cli_predict_ms_median``: ``skt predict``'s prediction of a 1000-point view with its
  default model (cleaning, sampling, skt_flow's 30 samples, the move and the probes' order),
  model loaded, process start excluded;
- ``sim_trials_per_min``: sim_eval trials (Panda; the oracle's and SCTDN's SKTs, every test
  object) per minute of wall time on ``compute.n_workers`` workers, over ``per_level`` test
  supports per level, with the default executor; ``*_previous`` with the one before it
  (``fallen_exit``), ``*_reference`` with the reference executor, ``sim_speedup_vs_*`` the
  ratios; ``sim_verdict_agreement`` (``*_previous``) the share of the reference executor's
  verdicts the default (previous) executor repeats (``sim_verdict_disagreements*``: the rest),
  ``sim_success_agreement`` (``*_previous``) the share whose outcome alone (hung or not) it
  repeats.
  Trials whose set-up finds no grasp are left out of all three
  (``sim_bench_setup_failures_excluded``; :func:`skt_lib.speed.sim_bench` says why);
- ``import_dense_s_median``: ``skt import-support`` / ``import-object`` of the mesh zoo's
  ≥ 250k-face cases (:mod:`skt_lib.cli.mesh_zoo`), wall seconds per import, process start
  included, one at a time (``import_dense_s``: each; ``import_dense_failed``: any refused).
Medians, because these machines are noisy. Each key's meaning: ``tools/docs_results.py``.
"""

import argparse
import json
import os
import platform
import subprocess
import sys
import tempfile
from pathlib import Path

from skt_lib import speed
from skt_lib.cli.mesh_zoo import bench_dense_imports
from skt_lib.cli.predict import DEFAULT_MODEL, median_predict_ms
from skt_lib.config.params_file import load_params
from skt_lib.io import read_npz, write_json_atomic
from skt_lib.perception.views import RENDER_SPEC
from skt_lib.planning import bench as planner_bench
from skt_lib.speed import flow_bench, render_bench, sctdn_bench
from stages._common import run_items


def rrt_bench(params, root: Path, per_level: int, n_skts: int) -> dict:
    """:func:`skt_lib.planning.bench.rrt_bench` with the stages' runner."""
    return planner_bench.rrt_bench(params, root, per_level, n_skts, run_items)


def sim_bench(params, root: Path, per_level: int) -> dict:
    """:func:`skt_lib.speed.sim_bench` with the stages' runner."""
    return speed.sim_bench(params, root, per_level, run_items)


def cli_bench(root: Path) -> dict:
    cloud = read_npz(sorted((root / "render_views").glob("*.npz"))[0], RENDER_SPEC)["points"][0]
    model = root / Path(DEFAULT_MODEL).relative_to("data")  # skt predict's default model
    return {"cli_predict_ms_median": median_predict_ms(model, cloud)}


#: The bench's parts, in the order they run, and the key prefixes each one writes.
PARTS = ("rrt", "sctdn", "flow", "cli", "sim", "render", "imports")
_PREFIXES = {"rrt": "rrt_", "sctdn": "sctdn_", "flow": "skt_flow_", "cli": "cli_", "sim": "sim_", "render": "render_",
             "imports": "import_"}


def _part_of(key: str) -> str | None:
    """The part that writes ``key`` (None: the run's own keys, e.g. ``machine``)."""
    return next((part for part, prefix in _PREFIXES.items() if key.startswith(prefix)), None)


def _in_tmp(fn):
    with tempfile.TemporaryDirectory() as tmp:
        return fn(Path(tmp))


def _git(*args) -> str:
    return subprocess.run(["git", *args], capture_output=True, text=True).stdout.strip()


def _commit() -> str:
    """The checked-out commit, ``+dirty`` when tracked files differ from it."""
    head = _git("rev-parse", "--short", "HEAD") or "unknown"
    return head + ("+dirty" if _git("status", "--porcelain", "--untracked-files=no") else "")


def _last_commit(path: Path) -> str:
    """The last commit that changed ``path`` ("unknown" outside git or when none did)."""
    return _git("log", "-1", "--format=%h", "--", str(path)) or "unknown"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="stages.bench", description=__doc__.splitlines()[0])
    ap.add_argument("--params", default="params.yaml")
    ap.add_argument("--data-root", default="data")
    ap.add_argument("--out", default="reports/bench/bench.json")
    ap.add_argument("--per-level", type=int, default=3, help="supports per difficulty level")
    ap.add_argument("--rrt-per-level", type=int, default=1,
                    help="supports per difficulty level of the planner bench (its reference "
                         "plans each SKT afresh: minutes per very hard support)")
    ap.add_argument("--rrt-skts", type=int, default=50,
                    help="SKTs per support of the planner bench (the paper's 50)")
    ap.add_argument("--parts", nargs="+", choices=PARTS, default=list(PARTS),
                    help="measure only these parts: their keys are replaced, every other "
                         "part's keys are kept from --out, and 'parts_commit' says which commit "
                         "measured each part (default: all, written afresh)")
    args = ap.parse_args(argv)
    params, root = load_params(args.params), Path(args.data_root)
    measure = {
        "rrt": lambda: rrt_bench(params, root, args.rrt_per_level, args.rrt_skts),
        "sctdn": lambda: sctdn_bench(root), "cli": lambda: cli_bench(root),
        "flow": lambda: flow_bench(root, params.sim_eval.flow_samples, params.common.seed,
                                   params.sim_eval.flow_contacts),
        "sim": lambda: sim_bench(params, root, args.per_level),
        "render": lambda: _in_tmp(lambda tmp: render_bench(params, root, args.per_level, tmp)),
        "imports": lambda: _in_tmp(lambda tmp: bench_dense_imports(Path(args.params), root, tmp))}
    out = Path(args.out)
    # a full run is fresh: a key this run does not measure must not survive from an old file
    old = json.loads(out.read_text()) if set(args.parts) != set(PARTS) and out.exists() else {}
    commit = _commit()
    bench = {k: v for k, v in old.items() if _part_of(k) not in (*args.parts, None)}
    # an older file without the record: its parts came from the last commit that changed it
    before = old.get("parts_commit") or {part: _last_commit(out) for part in PARTS}
    bench["parts_commit"] = ({part: before.get(part, "unknown") for part in PARTS}
                             | {part: commit for part in args.parts})
    for part in PARTS:
        if part in args.parts:
            bench |= measure[part]()
    bench["machine"] = (f"{platform.machine()}, {os.cpu_count()} cores, "
                        f"{params.compute.n_workers} workers")
    write_json_atomic(Path(args.out), bench)
    print(json.dumps(bench, indent=2, sort_keys=True))
    return 0


if __name__ == "__main__":
    sys.exit(main())
