"""Cost as the work grows: the whole pipeline at several support counts; each stage's wall
time, CPU time and peak memory into ``reports/bench/scaling.json`` and ``scaling.png``.

    .venv/bin/python -m tools.scaling --supports 240 60 120 --work /tmp/skt-scaling
    .venv/bin/python -m tools.scaling --fresh          # git clone + make repro, set-up included
    .venv/bin/python -m tools.scaling --plot-only      # redraw scaling.png from the JSON
    .venv/bin/python -m tools.scaling --paper-run reports/paper/run.json   # the measured 472

Each count runs in its own clone of the committed HEAD (this checkout's ``.venv`` linked
in) with ``mesh_gen.n_supports`` set and every other parameter as committed: the same
objects, the same test and validation set sizes. ``dvc repro`` runs under a monitor that
polls the process tree every ``POLL_S``: a stage is its ``python -m stages.<name>``
process with all its descendants (the workers). Its wall time runs from its first to its
last sighting; ``peak_rss_mb`` is the largest sum of their resident set sizes seen; its CPU
time sums each process's user + system time at its last sighting (a poll's worth may be
missed at the end of each process). Each count is written to the JSON as soon as it
finishes; counts already there are skipped (``--redo`` runs them again).

``--paper-run reports/paper/run.json`` records the measured paper preset (``make paper``'s
own per-stage figures, :mod:`tools.paper`) as ``paper_run``; ``--forget N …`` drops counts
measured on code that has since changed.

``--fresh`` measures what the README promises instead: a plain ``git clone`` of HEAD and
``make repro`` in it, the environment created from nothing (no ``.venv`` linked, pip's
downloads cached or not as on the machine), under the same monitor; the set-up is the time
before the first stage starts. It is written to ``fresh_repro`` in the JSON.
"""

import argparse
import json
import math
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import psutil
import yaml

from skt_lib.config import LEVELS

ROOT = Path(__file__).resolve().parents[1]
OUT = ROOT / "reports" / "bench"
POLL_S = 0.5
STAGE_CMD = re.compile(r"^stages\.([a-z_]+)$")


def stage_of(cmdline: list[str]) -> str | None:
    """The stage a process runs: ``python -m stages.<name>`` (None for any other process)."""
    for flag, arg in zip(cmdline, cmdline[1:]):
        if flag == "-m" and (m := STAGE_CMD.match(arg)):
            return m.group(1)
    return None


class TreeMonitor:
    """Per-stage wall time, CPU time and peak summed RSS of a process tree, by polling."""

    def __init__(self):
        self.stages: dict[str, dict] = {}
        self._cpu: dict[str, dict[int, float]] = {}

    def poll(self, root: psutil.Process, now: float) -> None:
        try:
            procs = [root, *root.children(recursive=True)]
        except psutil.NoSuchProcess:
            return
        for p in procs:
            try:
                name = stage_of(p.cmdline())
                if name is None:
                    continue
                tree = [p, *p.children(recursive=True)]
                rss, cpu = 0, self._cpu.setdefault(name, {})
                for q in tree:
                    with_times = q.cpu_times()
                    rss += q.memory_info().rss
                    cpu[q.pid] = with_times.user + with_times.system
            except (psutil.NoSuchProcess, psutil.AccessDenied, psutil.ZombieProcess):
                continue
            s = self.stages.setdefault(name, {"first": now, "last": now, "peak_rss": 0})
            s["last"], s["peak_rss"] = now, max(s["peak_rss"], rss)

    @property
    def first_seen(self) -> float:
        """When the first stage was first seen (seconds after the monitored command started)."""
        return min((s["first"] for s in self.stages.values()), default=float("nan"))

    def result(self) -> dict[str, dict]:
        """Per stage: wall, CPU and peak RSS, and ``first_s``, when it was first seen
        (seconds after the monitored command started: the order stages ran in, which a JSON
        file written with sorted keys does not keep)."""
        return {name: {"wall_s": s["last"] - s["first"] + POLL_S,
                       "cpu_s": float(sum(self._cpu[name].values())),
                       "peak_rss_mb": s["peak_rss"] / 2**20, "first_s": s["first"]}
                for name, s in self.stages.items()}


def run_monitored(cmd: list[str], cwd: Path, env: dict | None = None,
                  log: Path | None = None, mon: "TreeMonitor | None" = None
                  ) -> tuple[int, float, dict]:
    """Run ``cmd``; return (exit code, wall seconds, :meth:`TreeMonitor.result`)."""
    mon, t0 = mon or TreeMonitor(), time.monotonic()
    with open(log or "/dev/null", "w") as out:
        proc = subprocess.Popen(cmd, cwd=cwd, env=env, stdout=out, stderr=subprocess.STDOUT)
        root = psutil.Process(proc.pid)
        while proc.poll() is None:
            mon.poll(root, time.monotonic() - t0)
            time.sleep(POLL_S)
    return proc.returncode, time.monotonic() - t0, mon.result()


def prepare(work: Path, n: int) -> Path:
    """A clone of HEAD under ``work`` with ``mesh_gen.n_supports = n`` (fresh each time)."""
    d = work / f"supports_{n}"
    shutil.rmtree(d, ignore_errors=True)
    subprocess.run(["git", "clone", "-q", str(ROOT), str(d)], check=True)
    (d / ".venv").symlink_to(ROOT / ".venv")
    params = yaml.safe_load((d / "params.yaml").read_text())
    params["mesh_gen"]["n_supports"] = n
    (d / "params.yaml").write_text(yaml.safe_dump(params, sort_keys=False))
    return d


def fit(ns, values) -> tuple[float, float]:
    """Least-squares power law ``value = a · n^b`` through the points; returns (a, b)."""
    b, log_a = np.polyfit(np.log(ns), np.log(values), 1)
    return float(math.exp(log_a)), float(b)


#: The paper preset of docs/presets.md: supports, SKTs per support, test supports.
PAPER = {"n_supports": 472, "skts_per_support": 50, "n_test_supports": 60}


def extrapolate(data: dict) -> dict[str, float]:
    """Each stage's expected wall seconds at :data:`PAPER` — an extrapolation from the
    measured points, not a measurement: a power law in the number of supports fitted through
    them (:func:`fit`); ``rrt_skts`` times the paper's SKTs per support over the runs';
    ``sim_eval``, which runs a fixed test set, its mean time times the paper's test supports
    over the runs' (the same objects and methods)."""
    runs = sorted(data["runs"], key=lambda r: r["n_supports"])
    ns = [r["n_supports"] for r in runs]
    out = {}
    for s in data["stages"]:
        walls = [r["stages"][s]["wall_s"] for r in runs if s in r["stages"]]
        if len(walls) != len(runs) or len(runs) < 2:
            continue
        if s == "sim_eval":
            out[s] = float(np.mean(walls)) * PAPER["n_test_supports"] / data["n_test_supports"]
            continue
        a, b = fit(ns, walls)
        out[s] = a * PAPER["n_supports"] ** b
        if s == "rrt_skts":
            out[s] *= PAPER["skts_per_support"] / data["skts_per_support"]
    return out


def fresh_repro(work: Path) -> dict:
    """``git clone`` + ``make repro`` (module docs): wall time, set-up time and per stage."""
    d = work / "fresh"
    shutil.rmtree(d, ignore_errors=True)
    t0 = time.monotonic()
    subprocess.run(["git", "clone", "-q", str(ROOT), str(d)], check=True)
    commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=d, text=True,
                            capture_output=True, check=True).stdout.strip()
    log = work / "fresh-repro.log"  # outside the clone: its git status is part of the result
    print(f"fresh clone of {commit}: make repro in {d} (log {log})", flush=True)
    mon, cloned = TreeMonitor(), time.monotonic() - t0
    rc, wall, per_stage = run_monitored(["make", "repro"], d, None, log, mon)
    if rc != 0:
        raise SystemExit(f"make repro exited {rc}; see {log}")
    wall = time.monotonic() - t0
    dirty = changed_files(d)
    params = yaml.safe_load((d / "params.yaml").read_text())
    return {"commit": commit, "wall_s": wall, "setup_s": cloned + mon.first_seen,
            "stages": per_stage, "git_status_clean": not dirty, "git_status": dirty,
            "n_supports": total_supports(params), "skts_planned": skts_planned(params)}


def changed_files(repo: Path) -> list[str]:
    """``git status --porcelain`` of ``repo``, one ``"XY path"`` line each."""
    out = subprocess.run(["git", "status", "--porcelain"], cwd=repo, text=True,
                         capture_output=True, check=True).stdout
    return [line for line in out.splitlines() if line.strip()]


def fresh_summary(data: dict) -> str:
    """Markdown: the measured fresh-clone ``make repro`` (:func:`fresh_repro`)."""
    f = data.get("fresh_repro")
    if not f:
        return "Not measured yet: run `.venv/bin/python -m tools.scaling --fresh`."
    slow = sorted(f["stages"].items(), key=lambda kv: -kv[1]["wall_s"])[:3]
    return (f"Fresh `git clone` + `make repro` of commit {f['commit']} ({data['machine']}): "
            f"**{f['wall_s'] / 60:.1f} min**, set-up (environment from nothing) "
            f"{f['setup_s'] / 60:.1f} min of it; the longest stages "
            + ", ".join(f"`{s}` {v['wall_s'] / 60:.1f} min" for s, v in slow)
            + ("; `git status` clean after it." if f["git_status_clean"]
               else "; `git status` **not** clean after it ("
               + ", ".join(f"`{line[3:]}`" for line in f.get("git_status", [])) + ")."))


def table(data: dict) -> str:
    """Markdown: each stage's measured wall time per count, its fitted exponent, its peak RSS
    and its paper-preset extrapolation."""
    runs = sorted(data.get("runs", []), key=lambda r: r["n_supports"])
    if not runs:
        return ("No sweep over support counts is recorded: run `.venv/bin/python -m tools.scaling "
                "--supports N …`.")
    ns = [r["n_supports"] for r in runs]
    paper = extrapolate(data)
    lines = [f"Measured by `python -m tools.scaling` ({data['machine']}; commits "
             f"{', '.join(sorted({r['commit'] for r in runs}))}): `dvc repro` of the whole "
             "pipeline with only `mesh_gen.n_supports` changed. Wall time in minutes; peak RSS "
             "of the stage and its workers together, the largest over the counts; the last "
             f"column extrapolates to the paper preset ({PAPER['n_supports']} supports, "
             f"{PAPER['skts_per_support']} SKTs each, {PAPER['n_test_supports']} test supports; "
             "`tools/scaling.py: extrapolate`) — an extrapolation, not a measurement.", "",
             "| stage | " + " | ".join(f"{n} supports" for n in ns)
             + " | exponent | peak RSS (MB) | paper preset (extrapolated) |",
             "|---" * (len(ns) + 4) + "|"]
    for s in data["stages"]:
        if not all(s in r["stages"] for r in runs):
            continue
        walls = [r["stages"][s]["wall_s"] for r in runs]
        b = f"{fit(ns, walls)[1]:.2f}" if len(runs) > 1 else "–"
        extra = f"{paper[s] / 60:.0f} min" if s in paper else "–"
        lines.append(f"| `{s}` | " + " | ".join(f"{w / 60:.1f}" for w in walls)
                     + f" | {b} | {data['peak_rss_mb'][s]:.0f} | {extra} |")
    total = " | ".join(f"**{r['wall_s'] / 60:.1f}**" for r in runs)
    paper_h = f"**≈ {sum(paper.values()) / 3600:.1f} h**" if paper else "–"
    lines.append(f"| whole `dvc repro` | {total} | | | {paper_h} |")
    return "\n".join(lines)


def total_supports(params: dict) -> int:
    """Supports a run at ``params`` (a dict of params.yaml) generates: the ``n_supports`` the
    split is drawn from and the ``n_extra_train_supports``."""
    m = params["mesh_gen"]
    return m["n_supports"] + m.get("n_extra_train_supports", 0)


def skts_planned(params: dict) -> int:
    """SKT attempts of a run at ``params`` (a dict of params.yaml): test supports plan
    ``n_skts_per_test_support``, the others (extra training supports too) ``n_skts_per_support``."""
    r, m = params["rrt_skts"], params["mesh_gen"]
    n_test = len(LEVELS) * m["n_test_per_level"]
    return (r["n_skts_per_support"] * (total_supports(params) - n_test)
            + r.get("n_skts_per_test_support", r["n_skts_per_support"]) * n_test)


def paper_run(run_json: Path) -> dict:
    """The paper preset as ``make paper`` measured it (``reports/paper/run.json`` and the
    ``params.yaml`` beside it): per stage wall and CPU seconds and peak RSS, the pipeline's
    wall time (its stages' sum: set-up and the seed step not included)."""
    run = json.loads(run_json.read_text())
    params = yaml.safe_load((run_json.parent / "params.yaml").read_text())
    return {"commit": run["commit"][:7], "machine": run["machine"],
            "n_supports": total_supports(params), "skts_planned": skts_planned(params),
            "wall_s": run["pipeline_wall_s"], "seeds_wall_s": run.get("seeds_wall_s"),
            "stages": {k: {f: v[f] for f in ("wall_s", "cpu_s", "peak_rss_mb")}
                       for k, v in run["stages"].items()}}


def paper_table(data: dict) -> str:
    """Markdown: each stage of the measured paper run beside the fresh default's."""
    p, f = data.get("paper_run"), data.get("fresh_repro") or {}
    if not p:
        return "Not measured yet: run `make paper`, then `python -m tools.scaling --paper-run`."
    fs = f.get("stages", {})
    lines = [f"`make paper` at commit {p['commit']} ({p['machine']}; "
             f"[`reports/paper/run.json`](../reports/paper/run.json)) beside the fresh default "
             f"(`make repro` at {f.get('commit', '–')}). Minutes; CPU time is the stage's "
             "processes' user + system time (2 cores: at most twice the wall time, less where "
             "other work shared the machine).", "",
             "| stage | default wall | paper wall | paper CPU | paper peak RSS (MB) |",
             "|---|---|---|---|---|"]
    for name, st in p["stages"].items():
        d = fs.get(name, {}).get("wall_s")
        lines.append(f"| `{name}` | {'–' if d is None else f'{d / 60:.1f}'} | "
                     f"{st['wall_s'] / 60:.1f} | {st['cpu_s'] / 60:.1f} | "
                     f"{st['peak_rss_mb']:.0f} |")
    default = sum(v["wall_s"] for v in fs.values()) if fs else None
    lines.append(f"| **pipeline** | {'–' if default is None else f'**{default / 60:.1f}**'} | "
                 f"**{p['wall_s'] / 60:.1f}** | "
                 f"{sum(v['cpu_s'] for v in p['stages'].values()) / 60:.1f} | |")
    if p.get("seeds_wall_s"):
        lines += ["", "The seed step's segments since the models last changed (two more "
                      "training seeds trained and evaluated; before 762892f, `sim_eval` rerun "
                      f"after them too): {p['seeds_wall_s'] / 60:.1f} min."]
    return "\n".join(lines)


def presets_summary(data: dict) -> str:
    """Markdown for the README: the whole pipeline's measured time per count, and the paper
    preset's, labelled an extrapolation."""
    runs = sorted(data.get("runs", []), key=lambda r: r["n_supports"])
    if not runs and not data.get("fresh_repro") and not data.get("paper_run"):
        return "Not measured yet: run `.venv/bin/python -m tools.scaling`."
    paper = extrapolate(data) if runs else {}
    k = data.get("skts_per_support")
    default = yaml.safe_load((ROOT / "params.yaml").read_text())["mesh_gen"]["n_supports"]
    lines = ["| preset | supports | SKTs planned | whole pipeline, 2-core CPU machine |",
             "|---|---|---|---|"]
    lines += [f"| {'embedded default' if r['n_supports'] == default else 'default, resized'}"
              f" | {r['n_supports']} | {k * r['n_supports']:,} | {r['wall_s'] / 60:.0f} min "
              f"(measured at {r['commit']}) |" for r in runs]
    if f := data.get("fresh_repro"):  # the sizes it ran (older records: today's params)
        planned = skts_planned(yaml.safe_load((ROOT / "params.yaml").read_text()))
        lines.append(f"| embedded default, fresh clone + `make repro` (set-up included) | "
                     f"{f.get('n_supports', default)} | {f.get('skts_planned', planned):,} | "
                     f"{f['wall_s'] / 60:.1f} min (measured at {f['commit']}) |")
    if p := data.get("paper_run"):
        slowest = max(p["stages"], key=lambda k: p["stages"][k]["wall_s"])
        lines.append(f"| paper (`make paper`, one training seed) | {p['n_supports']} | "
                     f"{p['skts_planned']:,} | {p['wall_s'] / 3600:.1f} h (measured at "
                     f"{p['commit']}; `{slowest}` {p['stages'][slowest]['wall_s'] / 60:.0f} min "
                     "of it) |")
        if p.get("seeds_wall_s"):
            lines.append(f"| paper, seed step (two more training seeds) | {p['n_supports']} | "
                         f"– | {p['seeds_wall_s'] / 60:.0f} min "
                         f"(measured at {p['commit']}) |")
    elif paper:
        slowest = max(paper, key=paper.get)
        lines.append(f"| paper | {PAPER['n_supports']} | "
                     f"{PAPER['n_supports'] * PAPER['skts_per_support']:,} | ≈ "
                     f"{sum(paper.values()) / 3600:.1f} h (**extrapolated**; `{slowest}` "
                     f"{paper[slowest] / 3600:.1f} h of it) |")
    return "\n".join(lines)


def plot(data: dict, path: Path) -> None:
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    runs = sorted(data["runs"], key=lambda r: r["n_supports"])
    if not runs:
        _plot_presets(data, path, plt)
        return
    stages = [s for s in data["stages"] if all(s in r["stages"] for r in runs)]
    fig, (ax_t, ax_m) = plt.subplots(1, 2, figsize=(11, 4.5))
    ns = [r["n_supports"] for r in runs]
    for s in stages:
        ax_t.plot(ns, [r["stages"][s]["wall_s"] for r in runs], "o-", label=s)
        ax_m.plot(ns, [r["stages"][s]["peak_rss_mb"] for r in runs], "o-", label=s)
    ax_t.plot(ns, [r["wall_s"] for r in runs], "k--", label="whole dvc repro")
    for ax, what in ((ax_t, "wall time (s)"), (ax_m, "peak RSS, stage + workers (MB)")):
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xticks(ns, [str(n) for n in ns])
        ax.set_xlabel("supports")
        ax.set_ylabel(what)
        ax.grid(True, which="both", alpha=0.3)
    ax_t.legend(fontsize=7, ncol=2)
    fig.suptitle(f"Cost as the work grows ({data['machine']})")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _plot_presets(data: dict, path: Path, plt) -> None:
    """Per stage, the fresh default's and the paper run's wall time and peak RSS, side by
    side (two presets, not a size sweep: the paper plans 50 SKTs per support, the default 4)."""
    runs = [(f"default, {data['fresh_repro'].get('n_supports', '?')} supports (fresh make repro)",
             data["fresh_repro"]["stages"])] if data.get("fresh_repro") else []
    if p := data.get("paper_run"):
        runs.append((f"paper, {p['n_supports']} supports (make paper)", p["stages"]))
    if not runs:
        return
    stages = [s for s in data.get("stages", []) if any(s in st for _, st in runs)]
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.5))
    y = np.arange(len(stages))
    h = 0.8 / len(runs)
    for ax, key, what, scale in ((axes[0], "wall_s", "wall time (min)", 60.0),
                                 (axes[1], "peak_rss_mb", "peak RSS, stage + workers (MB)", 1.0)):
        for i, (label, st) in enumerate(runs):
            ax.barh(y + i * h, [st.get(s, {}).get(key, 0.0) / scale for s in stages], h,
                    label=label)
        ax.set_yticks(y + h * (len(runs) - 1) / 2, stages)
        ax.invert_yaxis()
        ax.set_xlabel(what)
        ax.grid(True, axis="x", alpha=0.3)
    axes[0].legend(fontsize=7)
    fig.suptitle(f"What each stage costs, default and paper preset ({data.get('machine', '')})")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--supports", type=int, nargs="+", default=[240, 60, 120])
    ap.add_argument("--work", type=Path, default=Path("/tmp/skt-scaling"))
    ap.add_argument("--out", type=Path, default=OUT)
    ap.add_argument("--redo", action="store_true", help="run counts already in the JSON again")
    ap.add_argument("--plot-only", action="store_true")
    ap.add_argument("--fresh", action="store_true",
                    help="only git clone + make repro at the committed params (module docs)")
    ap.add_argument("--paper-run", type=Path, metavar="RUN_JSON",
                    help="only record make paper's measured run (reports/paper/run.json)")
    ap.add_argument("--forget", type=int, nargs="+", default=[], metavar="N",
                    help="drop these support counts' runs (measured on code since changed)")
    args = ap.parse_args(argv)
    args.out.mkdir(parents=True, exist_ok=True)  # before a run of most of an hour, not after
    path = args.out / "scaling.json"
    stages = list(yaml.safe_load((ROOT / "dvc.yaml").read_text())["stages"])
    params = yaml.safe_load((ROOT / "params.yaml").read_text())
    data = json.loads(path.read_text()) if path.exists() else {"runs": []}
    data.update(stages=stages, skts_per_support=params["rrt_skts"]["n_skts_per_support"],
                n_test_supports=len(LEVELS) * params["mesh_gen"]["n_test_per_level"],
                machine=f"{psutil.cpu_count()} cores, {params['compute']['n_workers']} workers, "
                f"{psutil.virtual_memory().total / 2**30:.0f} GiB")
    if args.forget:
        data["runs"] = [r for r in data["runs"] if r["n_supports"] not in args.forget]
        if not data["runs"]:
            data.pop("peak_rss_mb", None)
    if args.paper_run or args.forget:
        if args.paper_run:
            data["paper_run"] = paper_run(args.paper_run)
        path.write_text(json.dumps(data, indent=2) + "\n")
        plot(data, args.out / "scaling.png")
        print(paper_table(data))
        return 0
    if args.fresh:
        args.work.mkdir(parents=True, exist_ok=True)
        data["fresh_repro"] = fresh_repro(args.work)
        path.write_text(json.dumps(data, indent=2) + "\n")
        print(fresh_summary(data))
        return 0
    if not args.plot_only:
        args.work.mkdir(parents=True, exist_ok=True)
        for n in args.supports:
            if not args.redo and any(r["n_supports"] == n for r in data["runs"]):
                print(f"{n} supports: already measured (--redo to run again)")
                continue
            d = prepare(args.work, n)
            commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=d, text=True,
                                    capture_output=True, check=True).stdout.strip()
            env = {**os.environ, "PATH": f"{d / '.venv' / 'bin'}:{os.environ['PATH']}"}
            print(f"{n} supports: dvc repro in {d} (log {d / 'repro.log'})", flush=True)
            rc, wall, per_stage = run_monitored([str(d / ".venv/bin/dvc"), "repro"], d, env,
                                                d / "repro.log")
            if rc != 0:
                print(f"{n} supports: dvc repro exited {rc}; see {d / 'repro.log'}")
                return rc
            data["runs"] = [r for r in data["runs"] if r["n_supports"] != n] + [{
                "n_supports": n, "commit": commit, "wall_s": wall, "stages": per_stage}]
            data["runs"].sort(key=lambda r: r["n_supports"])
            path.write_text(json.dumps(data, indent=2) + "\n")
            print(f"{n} supports: {wall / 60:.1f} min; "
                  + ", ".join(f"{s} {v['wall_s']:.0f} s" for s, v in per_stage.items()), flush=True)
    if data["runs"]:
        data["peak_rss_mb"] = {s: max(r["stages"][s]["peak_rss_mb"] for r in data["runs"]
                                      if s in r["stages"])
                               for s in stages if any(s in r["stages"] for r in data["runs"])}
        path.write_text(json.dumps(data, indent=2) + "\n")
        plot(data, args.out / "scaling.png")
    return 0


if __name__ == "__main__":
    sys.exit(main())

