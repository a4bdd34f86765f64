"""Mutation testing (``make mutation``): mutmut on the modules whose tests must be able to fail.

For each module, a scratch copy of the repository under ``.mutation/<name>/`` gets a
``[tool.mutmut]`` section that mutates only that module and runs only its fast unit tests
(listed below); ``mutmut run`` executes there, so the working tree is never touched. The
summary is merged per module into ``reports/tests/mutation.json``, replacing that module's
entry; entries of modules no longer in the repository are dropped::

    {module: {"killed", "survived", "timeout", "score", "equivalent", "no_tests", "other",
              "seconds", "tests"}}

``score = killed / (killed + survived)``, where ``survived`` includes mutants no selected
test executes (``no_tests``, also reported apart) and excludes the mutants judged
equivalent (``EQUIVALENT`` below; listed with the reason in ``reports/tests/mutation.md``).
``timeout`` mutants count as neither (mutmut reports them apart), nor do ``other`` ones
(per mutmut status, e.g. ``segfault``: the mutant crashed the test process). Not part of
``.ci/run``: minutes per module.

mutmut sends each mutant only to the tests that called the mutated function during its
own first run of the selected tests, in the pytest process (through the trampoline it
puts around every function): a test whose calls happen in a worker process (a stage's
pool, an isolated child) does not count, and a module none of whose selected tests call it
in-process gets no score. So a module's tests here call it directly.

    python tools/mutation.py                      # every module
    python tools/mutation.py skt_lib/geometry/skt.py --max-children 2
"""

import argparse
import json
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
WORK = ROOT / ".mutation"
OUT = ROOT / "reports" / "tests"

#: module → the fast unit tests that run against its mutants (pytest node ids or files)
MODULES: dict[str, list[str]] = {
    "skt_lib/sim/hanging.py": ["tests/sim/test_hanging.py"],
    "skt_lib/sim/execute.py": ["tests/sim/test_trials.py", "tests/sim/test_execute_parts.py"],
    "skt_lib/planning/collision.py": ["tests/planning/test_collision.py",
                                      "tests/planning/test_planning.py"],
    "skt_lib/geometry/skt.py": ["tests/geometry/test_skt.py",
                                "tests/geometry/test_fast_kernels.py"],
    "skt_lib/learning/pointnet2.py": ["tests/learning/test_pointnet2.py"],
}

#: surviving mutants judged equivalent (no observable behaviour changes): name → why.
#: Names are mutmut's (``module.x_function__mutmut_N``); re-check them when the module
#: changes, as mutant numbering follows the source.
EQUIVALENT: dict[str, str] = {
    "skt_lib.geometry.skt.x_keypoint_positions__mutmut_11":
        'einsum subscripts "nij,j->ni" → "NIJ,J->NI": the same contraction under renamed '
        "indices.",
    "skt_lib.geometry.skt.x_executed_path__mutmut_9":
        "np.asarray(positions, float) → np.asarray(positions, None): positions only flow into "
        "skt_frames, which converts to float64 itself (a float32 input is tested there).",
    "skt_lib.geometry.skt.x_executed_path__mutmut_11":
        "np.asarray(positions, float) → np.asarray(positions): as mutant 9.",
    **{f"skt_lib.geometry.skt.x__anchor__mutmut_{i}":
       "which entry of the rule rotation is tested for NaN ([0, 1] → [1, 1] or [0, 2]): "
       "rule_frames sets the whole y column to NaN where the rule is undefined and leaves it "
       "finite elsewhere (x is a finite unit vector), and z = x × y is NaN exactly where y is, "
       "so every y and z entry is NaN on the same rows."
       for i in (6, 7)},
    "skt_lib.geometry.skt.x_skt_frames_naive__mutmut_36":
        "prev = i − 1 if i > k → if i >= k: the loop visits k+1 … T−1 and k−1 … 0, never "
        "i = k, where alone > and >= differ.",
    **{f"skt_lib.geometry.skt.x_{f}__mutmut_20":
       "in the |a × b| < 1e-12 branch, c > 0 → c >= 0: differs only at a · b = 0 exactly, "
       "which with |a × b|² + (a · b)² = |a|²|b|² = 1 for the unit vectors the function is "
       "defined on cannot go with |a × b| < 1e-12 (only a zero vector could)."
       for f in ("minimal_rotation", "minimal_rotation_naive")},
    **{f"skt_lib.sim.execute.xǁ_Anchorǁ__init____mutmut_{i}":
       "the anchor's collision shape index −1 → −2 (19) or visual shape index −1 → +1 or −2 "
       "(20, 21): PyBullet attaches no shape for any of them (checked in a trial's world, "
       "the Panda's visual meshes loaded: getCollisionShapeData and getVisualShapeData are "
       "empty), and a visual shape would take no part in the physics anyway."
       for i in (19, 20, 21)},
    "skt_lib.sim.execute.x__attach__mutmut_12":
        "getLinkState(computeForwardKinematics=1 → 2): a flag, any non-zero value computes it.",
    **{f"skt_lib.sim.execute.x__attach__mutmut_{i}":
       "the jointAxis of a JOINT_FIXED constraint ([0, 0, 0] → None or a unit axis; 44, "
       "61–63) or its childFramePosition [0, 0, 0] → None (46, PyBullet's default): a fixed "
       "constraint has no axis; checked bit for bit over 100 steps holding a box, to a base "
       "and to a link."
       for i in (44, 46, 61, 62, 63)},
    **{f"skt_lib.sim.execute.x__choose_skt__mutmut_{i}":
       'the mover\'s name in the start-penetration check ("object" → "XXobjectXX" / '
       '"OBJECT"): only whether _blockers returns a non-empty string is used there.'
       for i in (33, 34)},
    "skt_lib.sim.execute.x__choose_skt__mutmut_38":
        "the floating hand's set-up result True → False: run_trial only asks whether it is "
        "None (and, with a robot, a GraspFailure); without a robot it is not used.",
    "skt_lib.sim.execute.x__choose_skt__mutmut_63":
        "_sweep_depth(stop_above=SWEEP_TOL_M) → the full sweep, compared with > SWEEP_TOL_M: "
        "the sweep stops early only at a pose deeper than the tolerance, so whether the "
        "result exceeds it is the same (only time changes).",
    **{f"skt_lib.sim.execute.x__sweep_depth__mutmut_{i}":
       "min_distance's query radius 0.0 → its default 0.05 (26) or 1.0 (27): a wider query "
       "adds only points at positive distance, whose negation never beats the running depth "
       "that starts at 0; penetrations come out the same (checked: −1, −2.5, −4, −6 mm "
       "bit for bit)."
       for i in (26, 27)},
    **{f"skt_lib.sim.execute.xǁ_Fallenǁ{m}__mutmut_7":
       "getAABB(body, -1) → getAABB(body): linkIndex defaults to −1 (the base)."
       for m in ("__init__", "__call__")},
    "skt_lib.sim.execute.x_run_trial__mutmut_44":
        'the row\'s initial failure_reason "" → "XXXX": every return goes through _end, '
        "which sets it.",
    **{f"skt_lib.sim.execute.x_run_trial__mutmut_{i}":
       "Panda(visual=reference) → visual None / the default False: the visual meshes are "
       "drawn, never simulated (checked: the reference executor's rows and traces, object "
       "and link poses, bit for bit on a success and a collision)."
       for i in (110, 114)},
    "skt_lib.learning.pointnet2.x_fps__mutmut_2":
        "torch.profiler label text only (\"pointnet2.fps\" → \"XXpointnet2.fpsXX\"): no output "
        "depends on it.",
    "skt_lib.learning.pointnet2.x_fps__mutmut_3": "profiler label case only, as x_fps__mutmut_2.",
    "skt_lib.learning.pointnet2.x_ball_query__mutmut_2": "profiler label text only.",
    "skt_lib.learning.pointnet2.x_ball_query__mutmut_3": "profiler label case only.",
    "skt_lib.learning.pointnet2.x__fps_torch__mutmut_20":
        'float("inf") → float("INF"): Python parses both to the same infinity.',
    "skt_lib.learning.pointnet2.x__fps_torch__mutmut_49":
        "dist.argmax(-1) → argmax(+1): dist is (B, N), so dim 1 is the last dim.",
    "skt_lib.learning.pointnet2.x_fps_naive__mutmut_9":
        ".sum(-1) → .sum(+1) on a (N, 3) difference: dim 1 is the last dim.",
    "skt_lib.learning.pointnet2.x_fps_naive__mutmut_26": "as x_fps_naive__mutmut_9.",
    "skt_lib.learning.pointnet2.xǁSetAbstractionǁforward__mutmut_30":
        "fps(...).to(xyz.device) → .to(None): a no-op either way, fps already returns indices "
        "on xyz's device (tested on the meta device).",
    "skt_lib.learning.pointnet2.xǁFeaturePropagationǁforward__mutmut_18":
        "d.topk(k, dim=-1, ...) → d.topk(k, ...): topk's default dim is -1.",
    "skt_lib.learning.pointnet2.xǁFeaturePropagationǁforward__mutmut_25":
        "w = 1/(d + ε) → 2/(d + ε): the weights are normalised on the next line; the factor "
        "cancels.",
    "skt_lib.learning.pointnet2.xǁFeaturePropagationǁforward__mutmut_26":
        "1/(d + 1e-8) → 1/(d − 1e-8): after normalisation the two differ by ~1e-8 relative "
        "(below float32 resolution); at d = 0 both give that point weight ≈ 1.",
    **{f"skt_lib.learning.pointnet2.x__fps_torch__mutmut_{i}":
       "an index/seed tensor (far, rows) created on the CPU instead of xyz's device: PyTorch "
       "indexing and setitem accept CPU index tensors for tensors on any device, so the "
       "result is identical (a host→device copy per use, not a different value); the "
       "tensors the result is built from are device-checked on the meta device."
       for i in (24, 27, 30, 32)},
    "skt_lib.sim.hanging.x_supporting_cluster__mutmut_29":
        'linkage(points, "single") → linkage(points): "single" is linkage\'s default method.',
    **{f"skt_lib.sim.hanging.x_observe_motion__mutmut_{i}":
       "a position argument of pb.invertTransform (16–18) or pb.multiplyTransforms (48–53) "
       "changed, but only the orientation ([1]) of the result is used, and it does not depend "
       "on the positions (checked bit-for-bit on random quaternions)."
       for i in (16, 17, 18, 48, 49, 50, 51, 52, 53)},
    "skt_lib.sim.hanging.x_observe_motion__mutmut_76":
        "np.clip(abs(dq[3]), 0.0, 1.0) → lower bound None: abs() is never below 0.",
    "skt_lib.sim.hanging.x_observe_motion__mutmut_77":
        "np.clip(..., 0.0, 1.0) → upper bound None: differs only if |dq[3]| rounds above 1, "
        "where arccos gives NaN instead of 0; max(ang, nan) keeps ang (NaN compares false) "
        "as max(ang, 0.0) does (ang ≥ 0), so the result is the same (only a RuntimeWarning).",
    "skt_lib.sim.hanging.x_observe_motion__mutmut_84":
        "upper clip bound 1.0 → 2.0: as x_observe_motion__mutmut_77.",
    "skt_lib.sim.hanging.x_check_hang__mutmut_70":
        "x_support > PLATE_X_M → >=: with SUPPORT_POSE_WORLD's x axis (−1, 0, 0) and origin "
        "x 0.75, x_support = 0.75 − x exactly (Sterbenz) for a double x ≈ 0.739, a multiple of "
        "2⁻⁵³; PLATE_X_M (0.011) is not, so x_support never equals it and > and >= agree.",
}


def _pyproject(module: str, tests: list[str]) -> str:
    text = (ROOT / "pyproject.toml").read_text()
    text = re.sub(r"(?ms)^\[tool\.mutmut\].*?(?=^\[|\Z)", "", text)
    return text + (
        "\n[tool.mutmut]\n"
        'source_paths = ["skt_lib"]\n'
        f"only_mutate = [{json.dumps(module)}]\n"
        'also_copy = ["stages", "viz"]\n'
        f"pytest_add_cli_args_test_selection = {json.dumps(tests)}\n"
        'pytest_add_cli_args = ["-p", "no:cacheprovider", "-q"]\n'
        "use_git_change_detection = false\n"
        # torch is not fork-safe: fork each mutant from a clean server, not from the
        # process that already ran the suite (with one intra-op thread, see below)
        'process_isolation = "forkserver"\n'
    )


def run_module(module: str, max_children: int, mutmut: str, rerun: bool = True) -> dict:
    name = module.removesuffix(".py").replace("/", ".")
    work = WORK / name
    tests = MODULES[module]
    if not rerun:  # re-summarise the last run (e.g. after judging more mutants equivalent)
        last = json.loads((OUT / "mutation.json").read_text())[module]
        return _summarise(module, name, work, mutmut, last["seconds"], last["tests"])
    shutil.rmtree(work, ignore_errors=True)
    work.mkdir(parents=True)
    for d in ("skt_lib", "stages", "viz", "tests"):
        shutil.copytree(ROOT / d, work / d, ignore=shutil.ignore_patterns("__pycache__"))
    (work / "pyproject.toml").write_text(_pyproject(module, tests))
    # one thread per mutant process: an OpenMP pool inherited across fork() deadlocks
    env = {**os.environ, "PYTHONDONTWRITEBYTECODE": "1", "OMP_NUM_THREADS": "1",
           "MKL_NUM_THREADS": "1"}
    t0 = time.perf_counter()
    with (work / "mutmut-run.log").open("w") as log:
        proc = subprocess.run([mutmut, "run", "--max-children", str(max_children)], cwd=work,
                              env=env, stdout=log, stderr=subprocess.STDOUT)
    seconds = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"ERROR: mutmut run failed for {module} (see {work / 'mutmut-run.log'})")
    return _summarise(module, name, work, mutmut, seconds, tests)


def _summarise(module: str, name: str, work: Path, mutmut: str, seconds: float,
               tests: list[str]) -> dict:
    res = subprocess.run([mutmut, "results", "--all", "true"], cwd=work, capture_output=True,
                         text=True, check=True).stdout
    status = dict(re.findall(r"^\s*(\S+): (.+?)\s*$", res, flags=re.M))
    status = {k: v for k, v in status.items() if k.startswith(name + ".")}
    equivalent = sorted(k for k, v in status.items() if v == "survived" and k in EQUIVALENT)
    count = lambda s: sum(v == s for k, v in status.items() if k not in equivalent)  # noqa: E731
    # a mutant no selected test executes survives too: counted in ``survived`` (and apart)
    killed, survived = count("killed"), count("survived") + count("no tests")
    survivors = sorted(k for k, v in status.items()
                       if v in ("survived", "no tests") and k not in equivalent)
    return {"killed": killed, "survived": survived, "timeout": count("timeout"),
            "score": round(killed / max(1, killed + survived), 4),
            "equivalent": len(equivalent), "no_tests": count("no tests"),
            "other": {s: count(s) for s in sorted(set(status.values()))
                      if s not in ("killed", "survived", "timeout", "no tests")},
            "seconds": round(seconds, 1), "tests": tests,
            "_survivors": survivors, "_equivalent": equivalent}


def write_reports(results: dict, out: Path = OUT, root: Path = ROOT) -> None:
    """Merge ``results`` (module → :func:`_summarise`'s dict) into ``out/mutation.{json,md}``:
    each module's entry and section is replaced whole by its latest run, the others kept —
    except those of a module no longer in the repository (no file ``root/<module>``: a
    deleted or moved module), which are dropped."""
    out.mkdir(parents=True, exist_ok=True)
    path = out / "mutation.json"
    summary = json.loads(path.read_text()) if path.is_file() else {}
    details = {}
    for module, r in results.items():
        details[module] = (r.pop("_survivors"), r.pop("_equivalent"))
        summary[module] = r
    summary = {m: r for m, r in summary.items() if (root / m).is_file()}
    path.write_text(json.dumps(dict(sorted(summary.items())), indent=2) + "\n")
    md = out / "mutation.md"
    old = md.read_text() if md.is_file() else ""
    sections = dict(re.findall(r"(?ms)^## `(.+?)`\n(.*?)(?=^## `|\Z)", old))
    sections = {m: text for m, text in sections.items() if m in summary}
    for module, (survivors, equivalent) in details.items():
        if module not in summary:
            continue
        r = summary[module]
        lines = [f"killed {r['killed']}, survived {r['survived']}, timeout {r['timeout']}, "
                 f"equivalent {r['equivalent']}, score {r['score']:.3f}; {r['seconds']:.0f} s "
                 f"wall; tests: {', '.join(f'`{t}`' for t in r['tests'])}.", ""]
        lines += ["Equivalent (excluded from the score):", ""]
        lines += [f"- `{k}`: {EQUIVALENT[k]}" for k in equivalent] or ["- none"]
        lines += ["", "Surviving (not judged equivalent; `mutmut show <name>` in "
                  f"`.mutation/{module.removesuffix('.py').replace('/', '.')}`):", ""]
        lines += [f"- `{k}`" for k in survivors] or ["- none"]
        sections[module] = "\n".join(lines) + "\n\n"
    head = ("# Mutation testing (`make mutation`)\n\n"
            "mutmut mutates one module at a time and runs its fast unit tests; "
            "score = killed / (killed + survived), equivalent mutants excluded (a mutant no "
            "selected test runs counts as survived). Wall times: the 2-core development "
            "machine, shared with other jobs. Summary: `mutation.json`. Generated by "
            "`tools/mutation.py` (`make mutation`, or `MODULES=...` for some).\n\n")
    md.write_text(head + "".join(f"## `{m}`\n{sections[m]}" for m in sorted(sections)))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("modules", nargs="*", default=list(MODULES), help="modules (default: all)")
    ap.add_argument("--max-children", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--no-run", action="store_true",
                    help="re-summarise the last run in .mutation/ (after editing EQUIVALENT)")
    args = ap.parse_args(argv)
    unknown = [m for m in args.modules if m not in MODULES]
    if unknown:
        print(f"ERROR: no test list for {unknown}; known: {list(MODULES)}", file=sys.stderr)
        return 2
    mutmut = shutil.which("mutmut", path=str(Path(sys.executable).parent)) or "mutmut"
    results = {}
    for m in args.modules:
        results[m] = run_module(m, args.max_children, mutmut, rerun=not args.no_run)
        print(f"{m}: {json.dumps({k: v for k, v in results[m].items() if not k.startswith('_')})}",
              file=sys.stderr)
    write_reports(results)
    return 0


if __name__ == "__main__":
    sys.exit(main())
