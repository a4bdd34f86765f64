"""``make paper``: the paper preset, end to end, in a workspace of its own.

    .venv/bin/python -m tools.paper                 # run (or resume) it, then collect its reports
    .venv/bin/python -m tools.paper --seeds 3       # … and the learned methods' extra seeds
    .venv/bin/python -m tools.paper --collect-only  # copy an up-to-date workspace's reports

The workspace (``paper/`` by default, git- and DVC-ignored) is a ``git clone`` of this
checkout's HEAD, so the run is of committed code only; its ``params.yaml`` is the committed
``params.yaml`` with ``params.paper.yaml``'s overrides (and any ``-S key=value``) applied. The
pipeline is then ``dvc repro`` there, with the workspace's own ``dvc.lock``, ``data/`` and
DVC cache: the default's ``dvc.lock``, ``data/`` and ``reports/`` are never touched.

Resuming: run it again. A later HEAD is checked out in the workspace with its ``dvc.lock``
kept, so DVC reruns exactly the stages whose code, params or inputs changed; a stage killed
mid-run resumes from its finished items (``skt_lib/resume.py``) and ends with the bytes of an
uninterrupted run.

Every ``dvc repro`` (a *segment*) runs under :class:`tools.scaling.TreeMonitor`: each stage's
wall time, CPU time and peak memory (the stage's process and its workers) are appended to
``<workspace>/logs/paper-segments.json``. When the pipeline is up to date the reports are
collected into ``reports/paper/``: every stage's report folder, the workspace's ``params.yaml``
and ``dvc.lock``, and ``run.json`` (commit, machine, segments, per-stage totals), summarised
in ``reports/paper/README.md``.
"""

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import time
from pathlib import Path

import psutil
import yaml

from skt_lib.io import write_json_atomic
from tools.scaling import POLL_S, TreeMonitor
from tools.seed_compare import DEFAULT_A, DEFAULT_B, compare_document, seed_pairs

ROOT = Path(__file__).resolve().parents[1]
PRESET = ROOT / "params.paper.yaml"
STAGES = ("mesh_gen", "contact_sim", "rotation_extraction", "rrt_skts", "render_views",
          "affordance_maps", "clustering", "train", "train_baselines", "sim_eval")
#: How often a running segment's figures are saved (s): what a kill loses at most.
SAVE_S = 5.0


def git(*args: str, cwd: Path) -> str:
    return subprocess.run(["git", *args], cwd=cwd, check=True, text=True,
                          capture_output=True).stdout.strip()


def merge(base: dict, over: dict, where: str = "") -> dict:
    """``base`` with ``over``'s values put in, recursively; a key ``base`` lacks is an error
    naming it (a typo would otherwise silently run the default)."""
    out = dict(base)
    for key, value in over.items():
        name = f"{where}{key}"
        if key not in base:
            raise SystemExit(f"ERROR: {name}: not a key of params.yaml")
        out[key] = merge(base[key], value, f"{name}.") if isinstance(value, dict) else value
    return out


def set_overrides(pairs: list[str]) -> dict:
    """``-S section.key=value`` (value read as YAML) → a nested dict."""
    out: dict = {}
    for pair in pairs:
        key, sep, text = pair.partition("=")
        if not sep or not key:
            raise SystemExit(f"ERROR: -S {pair!r}: expected section.key=value")
        *path, last = key.split(".")
        node = out
        for part in path:
            node = node.setdefault(part, {})
        node[last] = yaml.safe_load(text)
    return out


def sync_workspace(source: Path, ws: Path) -> str:
    """Clone ``source`` into ``ws``, or move an existing workspace to ``source``'s HEAD while
    keeping what its runs wrote (``dvc.lock`` and ``reports/``: DVC compares them with what
    made its outputs); returns the commit."""
    commit = git("rev-parse", "HEAD", cwd=source)
    if not (ws / ".git").is_dir():
        if ws.exists() and any(ws.iterdir()):
            raise SystemExit(f"ERROR: {ws}: exists and is not a paper workspace (no .git)")
        subprocess.run(["git", "clone", "-q", "--no-checkout", str(source), str(ws)], check=True)
        subprocess.run(["git", "checkout", "-q", "--detach", commit], cwd=ws, check=True)
    elif git("rev-parse", "HEAD", cwd=ws) != commit:
        subprocess.run(["git", "fetch", "-q", str(source), commit], cwd=ws, check=True)
        kept = ws / "logs" / "kept"
        shutil.rmtree(kept, ignore_errors=True)
        kept.mkdir(parents=True)
        for name in ("dvc.lock", "reports"):
            if (ws / name).exists():
                (ws / name).rename(kept / name)
        subprocess.run(["git", "checkout", "-q", "-f", "--detach", commit], cwd=ws, check=True)
        for name in ("dvc.lock", "reports"):
            if (kept / name).exists():
                shutil.rmtree(ws / name, ignore_errors=True)
                (kept / name).rename(ws / name)
        kept.rmdir()
    venv = source / ".venv"
    if venv.is_dir() and not (ws / ".venv").exists():
        (ws / ".venv").symlink_to(venv.resolve())
    return commit


def write_params(ws: Path, preset: Path, overrides: dict) -> dict:
    """The workspace's ``params.yaml``: its committed one, the preset, then ``overrides``."""
    base = yaml.safe_load(git("show", "HEAD:params.yaml", cwd=ws))
    params = merge(merge(base, yaml.safe_load(preset.read_text()) or {}), overrides)
    text = ("# The paper preset: params.yaml with params.paper.yaml applied (tools/paper.py).\n"
            + yaml.safe_dump(params, sort_keys=False))
    path = ws / "params.yaml"
    if not path.exists() or path.read_text() != text:  # unchanged bytes: no needless rerun
        path.write_text(text)
    return params


def append_segment(ws: Path, segment: dict) -> list[dict]:
    path = ws / "logs" / "paper-segments.json"
    segments = json.loads(path.read_text()) if path.exists() else []
    segments.append(segment)
    write_json_atomic(path, segments)
    return segments


def run_segment(ws: Path, commit: str, cmd: list[str], kind: str, log: Path) -> int:
    """``cmd`` in the workspace under the monitor; its figures appended as a segment. While it
    runs they are kept in ``logs/paper-segment.partial.json`` (every :data:`SAVE_S`), so a
    killed run's segment is appended, with ``exit_code`` null, by the next one; they are also
    saved as soon as a stage is first seen, so a stage killed in its first seconds counts."""
    partial = ws / "logs" / "paper-segment.partial.json"
    if partial.exists():
        append_segment(ws, json.loads(partial.read_text()))
        partial.unlink()
    env = dict(os.environ, PATH=f"{ws / '.venv' / 'bin'}{os.pathsep}{os.environ['PATH']}")
    print(f"paper: {' '.join(cmd)} in {ws} (log {log})", flush=True)
    log.parent.mkdir(parents=True, exist_ok=True)
    segment = {"kind": kind, "commit": commit, "cmd": cmd[1:], "started_unix": round(time.time()),
               "wall_s": 0.0, "exit_code": None, "stages": {}}
    mon, t0, saved = TreeMonitor(), time.monotonic(), 0.0
    with open(log, "a") as out:
        out.write(f"\n=== {time.strftime('%Y-%m-%d %H:%M:%S')} {' '.join(cmd)}\n")
        out.flush()
        proc = subprocess.Popen(cmd, cwd=ws, env=env, stdout=out, stderr=subprocess.STDOUT)
        root = psutil.Process(proc.pid)
        while proc.poll() is None:
            now = time.monotonic() - t0
            seen = len(mon.stages)
            mon.poll(root, now)
            if now - saved >= SAVE_S or len(mon.stages) > seen:  # a stage begins: saved at once
                write_json_atomic(partial, segment | {"wall_s": now, "stages": mon.result()})
                saved = now
            time.sleep(POLL_S)
    append_segment(ws, segment | {"wall_s": time.monotonic() - t0, "exit_code": proc.returncode,
                                  "stages": mon.result()})
    partial.unlink(missing_ok=True)
    return proc.returncode


def clear_stale_rwlock(ws: Path) -> None:
    """Remove DVC's ``.dvc/tmp/rwlock`` when it names processes and every one is gone: a
    killed run leaves it behind, and DVC counts a killed process that nobody reaped (a zombie,
    where the container's init does not reap) as alive, refusing to run. A lock naming none
    (what DVC leaves after a run that ended) is left as it is."""
    path = ws / ".dvc" / "tmp" / "rwlock"
    if not path.exists():
        return
    try:
        lock = json.loads(path.read_text() or "{}")
    except json.JSONDecodeError:
        lock = {}
    infos = [*lock.get("write", {}).values(),
             *(i for infos in lock.get("read", {}).values() for i in infos)]
    if infos and not any(_alive(i.get("pid")) for i in infos):
        print(f"paper: removing {path}, left by a killed run", flush=True)
        path.unlink()


def _alive(pid) -> bool:
    try:
        return psutil.Process(int(pid)).status() != psutil.STATUS_ZOMBIE
    except (psutil.NoSuchProcess, TypeError, ValueError):
        return False


def up_to_date(ws: Path) -> bool:
    out = subprocess.run([str(ws / ".venv" / "bin" / "dvc"), "status", "--quiet"], cwd=ws)
    return out.returncode == 0


def stage_totals(segments: list[dict]) -> dict[str, dict]:
    """Each stage's wall and CPU seconds for its last completed run: summed over the pipeline
    segments from the one after its previous completion to the one it completed in (a stage
    killed and resumed counts both parts, at whichever commits they ran: the workspace keeps
    a stage's outputs while its code is unchanged), and its largest peak memory. A stage
    completed in a segment that saw a later stage begin (stages in the order first seen; in a
    segment recorded without it, in pipeline order), or that exited 0. A stage killed and
    then rerun from scratch because its code changed counts the killed part too."""
    done: dict[str, dict] = {}
    acc: dict[str, dict] = {}
    for seg in segments:
        if seg["kind"] != "pipeline":
            continue
        # the order the stages ran in: first seen (a segment recorded without it: the
        # pipeline's order; saved segments' keys are sorted)
        order = sorted(seg["stages"], key=lambda k: (seg["stages"][k].get("first_s", 0.0),
                                                     STAGES.index(k) if k in STAGES else 99))
        for i, name in enumerate(order):
            s = seg["stages"][name]
            t = acc.setdefault(name, {"wall_s": 0.0, "cpu_s": 0.0, "peak_rss_mb": 0.0,
                                      "segments": 0, "commits": []})
            t["wall_s"] += s["wall_s"]
            t["cpu_s"] += s["cpu_s"]
            t["peak_rss_mb"] = max(t["peak_rss_mb"], s["peak_rss_mb"])
            t["segments"] += 1
            if seg["commit"] not in t["commits"]:
                t["commits"].append(seg["commit"])
            if i < len(order) - 1 or seg["exit_code"] == 0:
                done[name] = acc.pop(name)
    return {name: done[name] for name in STAGES if name in done}


#: Reports in the workspace that ``make paper`` does not write: the clone's copies of the
#: default's (the benchmarks, the tests' mutation scores, ``make camera``, ``make
#: train-diagnostics``, ``tools.hidden_views``) and of the last collected paper run
#: (``paper``), which must not pass for this run's.
NOT_COLLECTED = ("bench", "tests", "camera", "paper", "diagnostics.*", "template_reach.*",
                 "hidden_views.*")


def _written(ws: Path, path: str) -> bool:
    """Whether anything under ``path`` in the workspace differs from its checkout (written by
    the run) or is new."""
    return bool(git("status", "--porcelain", "--untracked-files=all", "--", path, cwd=ws).strip())


def merged_seeds(ws: Path) -> bool:
    """Whether the workspace's ``reports/seeds`` are this run's: written by its seed step (not
    the default's, as the clone checked them out) and merged by its ``sim_eval`` (whose
    metrics' ``seeds`` block is ``ok``; an earlier seed step's, on models since retrained, is
    ``stale`` there and is left out of the collection rather than reported)."""
    if not _written(ws, "reports/seeds"):
        return False
    metrics = ws / "reports" / "sim_eval" / "metrics.json"
    return metrics.is_file() and \
        (json.loads(metrics.read_text()).get("seeds") or {}).get("status") == "ok"


def seed_segments(segments: list[dict]) -> list[dict]:
    """The seed step's segments that made the current seeds: the last run of seed segments,
    resumed across pipeline segments that ran nothing, back to the pipeline segment before it
    that ran a stage (a finished seed step's merging ``sim_eval``, or the models); none when a
    stage other than ``sim_eval`` ran after them (a rerun model stage makes them stale;
    ``sim_eval`` runs after them and merges them)."""
    out = []
    for s in reversed(segments):
        ran = set(s.get("stages") or ())
        if s["kind"] == "seeds":
            out.append(s)
        elif ran and out:
            break
        elif ran - {"sim_eval"}:
            return []
    return out[::-1]


def collect(ws: Path, dest: Path, commit: str) -> dict:
    """The workspace's reports, params, lock and run figures into ``dest`` (replaced whole)."""
    segments = json.loads((ws / "logs" / "paper-segments.json").read_text())
    totals = stage_totals(segments)
    seeds = seed_segments(segments)
    run = {
        "commit": commit,
        "machine": f"{platform.machine()}, {os.cpu_count()} cores, "
                   f"{psutil.virtual_memory().total / 2**30:.0f} GiB",
        "stages": totals,
        "pipeline_wall_s": sum(t["wall_s"] for t in totals.values()),
        "seeds_wall_s": sum(s["wall_s"] for s in seeds) if seeds else None,
        "segments": [{k: v for k, v in s.items() if k != "stages"} for s in segments],
    }
    tmp = dest.with_name(dest.name + ".tmp")
    shutil.rmtree(tmp, ignore_errors=True)
    shutil.copytree(ws / "reports", tmp, ignore=shutil.ignore_patterns(*NOT_COLLECTED))
    if not merged_seeds(ws):
        shutil.rmtree(tmp / "seeds", ignore_errors=True)
    elif (tmp / "seeds" / "seed_runs.json").is_file():  # the default predictor against the rival
        by_seed = seed_pairs(ws)
        write_json_atomic(tmp / "seeds" / "compare.json",
                          compare_document(by_seed, DEFAULT_A, DEFAULT_B))
    for name in ("params.yaml", "dvc.lock"):
        shutil.copy2(ws / name, tmp / name)
    (tmp / "run.json").write_text(json.dumps(run, indent=1) + "\n")  # stages in pipeline order
    (tmp / "README.md").write_text(summary(run))
    shutil.rmtree(dest, ignore_errors=True)
    tmp.replace(dest)
    return run


def summary(run: dict) -> str:
    lines = [
        "# The paper preset's run (`make paper`)", "",
        f"Collected at commit `{run['commit'][:7]}`, {run['machine']}; a stage's outputs "
        "come from the commits in its row (the workspace keeps a stage's outputs while its "
        "code and parameters are unchanged: DVC decides). The parameters are "
        "[`params.yaml`](params.yaml) (the committed default with `params.paper.yaml` "
        "applied) and the outputs' hashes [`dvc.lock`](dvc.lock). Each stage's report is in "
        "its folder here.", "",
        "| stage | wall (min) | CPU (min) | peak RSS (MB) | segments | commits |",
        "|---|---|---|---|---|---|",
    ]
    for name, t in run["stages"].items():
        lines.append(f"| [`{name}`]({name}/report.md) | {t['wall_s'] / 60:.1f} | "
                     f"{t['cpu_s'] / 60:.1f} | {t['peak_rss_mb']:.0f} | {t['segments']} | "
                     + ", ".join(f"`{c[:7]}`" for c in t["commits"]) + " |")
    lines.append(f"| **pipeline** | **{run['pipeline_wall_s'] / 60:.1f}** | | | | |")
    if run["seeds_wall_s"] is not None:
        lines.append(f"| extra training seeds (`tools.seed_sweep` segments) | "
                     f"{run['seeds_wall_s'] / 60:.1f} | | | | |")
    lines += ["", "Wall time is the stage's process tree from its first to its last sighting "
              "(polled every 0.5 s), summed over the segments (a killed and resumed stage has "
              "two); set-up (the environment) is not included. Wall time also counts whatever "
              "else the machine ran meanwhile; CPU time does not.", ""]
    return "\n".join(lines)


def steps(dvc: str, py: str, until: str | None, seeds: int) -> list[tuple[list[str], str]]:
    """The segments of a run, as ``(command, kind)``: ``dvc repro`` (up to ``until``); with
    ``seeds`` > 1 the models first (every stage but ``sim_eval``), then the extra seeds
    (``tools.seed_sweep``: it needs only those stages up to date), then ``sim_eval`` once,
    which merges them — rather than ``sim_eval`` twice, before and after the seeds."""
    if until or seeds <= 1:
        return [([dvc, "repro", *([until] if until else [])], "pipeline")]
    return [([dvc, "repro", *[s for s in STAGES if s != "sim_eval"]], "pipeline"),
            ([py, "-m", "tools.seed_sweep", "--seeds", str(seeds)], "seeds"),
            ([dvc, "repro"], "pipeline")]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="tools.paper", description=__doc__.splitlines()[0])
    ap.add_argument("--workspace", type=Path, default=ROOT / "paper")
    ap.add_argument("--source", type=Path, default=ROOT, help="the git checkout whose HEAD runs")
    ap.add_argument("--preset", type=Path, default=PRESET)
    ap.add_argument("--reports", type=Path, default=ROOT / "reports" / "paper",
                    help="where the collected reports go")
    ap.add_argument("-S", "--set", action="append", default=[], metavar="KEY=VALUE",
                    help="one more parameter override, e.g. -S compute.backend=dask")
    ap.add_argument("--until", default=None, metavar="STAGE",
                    help="stop after this stage (nothing is collected)")
    ap.add_argument("--seeds", type=int, default=1,
                    help="training seeds in all for the learned methods (1: the pipeline's own)")
    ap.add_argument("--collect-only", action="store_true")
    args = ap.parse_args(argv)
    ws = args.workspace.resolve()
    commit = sync_workspace(args.source.resolve(), ws)
    write_params(ws, args.preset, set_overrides(args.set))
    log = ws / "logs" / "paper.log"
    dvc = str(ws / ".venv" / "bin" / "dvc")
    clear_stale_rwlock(ws)
    if not args.collect_only:
        py = str(ws / ".venv" / "bin" / "python")
        for cmd, kind in steps(dvc, py, args.until, args.seeds):
            if rc := run_segment(ws, commit, cmd, kind, log):
                print(f"ERROR: {' '.join(cmd[1:])} exited {rc} in {ws}; see {log}",
                      file=sys.stderr)
                return rc
        if args.until:
            return 0
    if not up_to_date(ws):
        print(f"ERROR: {ws}: the pipeline is not up to date (dvc status); run make paper",
              file=sys.stderr)
        return 2
    run = collect(ws, args.reports, commit)
    print(f"paper: pipeline {run['pipeline_wall_s'] / 60:.1f} min; reports in {args.reports}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
