"""The dask backend on a real cluster: a `dask scheduler` and two `dask worker` processes
(the `distributed` CLI, on localhost), started here as subprocesses.

A stage run with `compute.backend: dask` + `compute.scheduler_address` must write the same
bytes as the local backend, also when a worker dies mid-stage (Dask reruns its tasks), and
its progress bar must still count every item.
"""

import copy
import json
import os
import re
import signal
import subprocess
import sys
import threading
import time
from contextlib import contextmanager
from pathlib import Path

import pytest
import yaml

from stages import mesh_gen, render_views
from tests.conftest import TINY, assert_same_tree

REPO = Path(__file__).resolve().parents[1]
N_WORKERS = 2
START_TIMEOUT_S = 90


def _dask_cli() -> list[str]:
    exe = Path(sys.executable).parent / "dask"
    return [str(exe)] if exe.is_file() else [sys.executable, "-m", "dask"]


class Cluster:
    """A scheduler and worker processes, each in its own process group (a worker's nanny
    and its worker process die together, as when its machine goes away)."""

    def __init__(self, root: Path):
        self.root = root
        self.procs: dict[str, subprocess.Popen] = {}
        self.logs: dict[str, Path] = {}
        self.env = dict(os.environ, PYTHONPATH=os.pathsep.join(
            [str(REPO)] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]))
        self.address: str | None = None
        self.client = None
        self._n_started = 0

    def _spawn(self, name: str, args: list[str]) -> None:
        log = self.root / f"{name}.log"
        with open(log, "wb") as fh:  # the child keeps its own descriptor
            self.procs[name] = subprocess.Popen(
                _dask_cli() + args, cwd=REPO, env=self.env, stdout=fh, stderr=subprocess.STDOUT,
                stdin=subprocess.DEVNULL, start_new_session=True)
        self.logs[name] = log

    def start(self) -> None:
        sched_file = self.root / "scheduler.json"
        self._spawn("scheduler", ["scheduler", "--host", "127.0.0.1", "--port", "0",
                                  "--no-dashboard", "--scheduler-file", str(sched_file)])
        deadline = time.monotonic() + START_TIMEOUT_S
        while not (sched_file.is_file() and sched_file.stat().st_size):
            self._check_alive("scheduler")
            if time.monotonic() > deadline:
                raise RuntimeError(f"dask scheduler wrote no {sched_file} in {START_TIMEOUT_S} s"
                                   + self.log_text())
            time.sleep(0.1)
        time.sleep(0.1)  # the file is written in one go, but be sure it is complete
        self.address = json.loads(sched_file.read_text())["address"]
        from distributed import Client

        self.client = Client(self.address, set_as_default=False, timeout=START_TIMEOUT_S)
        self.ensure_workers(N_WORKERS)

    def start_worker(self) -> str:
        name = f"worker{self._n_started}"
        self._n_started += 1
        self._spawn(name, ["worker", self.address, "--nworkers", "1", "--nthreads", "1",
                           "--no-dashboard", "--host", "127.0.0.1", "--name", name,
                           "--local-directory", str(self.root / name), "--death-timeout", "60"])
        return name

    def live_workers(self) -> list[str]:
        return [n for n, p in self.procs.items() if n != "scheduler" and p.poll() is None]

    def ensure_workers(self, n: int) -> None:
        """Start workers until ``n`` run, then wait until the scheduler sees ``n``."""
        while len(self.live_workers()) < n:
            self.start_worker()
        deadline = time.monotonic() + START_TIMEOUT_S
        while len(self.client.scheduler_info(n_workers=-1)["workers"]) != n:
            self._check_alive(*self.live_workers(), "scheduler")
            if time.monotonic() > deadline:
                seen = len(self.client.scheduler_info(n_workers=-1)["workers"])
                raise RuntimeError(f"the scheduler sees {seen} of {n} dask workers after "
                                   f"{START_TIMEOUT_S} s" + self.log_text())
            time.sleep(0.1)

    def _check_alive(self, *names: str) -> None:
        for name in names:
            if self.procs[name].poll() is not None:
                raise RuntimeError(f"dask {name} exited with {self.procs[name].returncode}"
                                   + self.log_text())

    def worker_procs(self) -> dict[str, str]:
        """{worker address: name of the process (group) that runs it}."""
        groups = {p.pid: n for n, p in self.procs.items()}
        return {addr: groups[os.getpgid(pid)] for addr, pid in self.client.run(os.getpid).items()}

    def kill(self, name: str) -> None:
        os.killpg(self.procs[name].pid, signal.SIGKILL)
        self.procs[name].wait(10)

    def log_text(self) -> str:
        out = []
        for name, path in self.logs.items():
            text = path.read_text(errors="replace") if path.is_file() else "(no log)"
            out.append(f"\n----- dask {name} ({path}) -----\n{text[-6000:]}")
        return "".join(out)

    @contextmanager
    def logs_on_failure(self):
        """Print the cluster's logs if the block fails (pytest shows them with the failure)."""
        try:
            yield
        except BaseException:
            print(self.log_text())
            raise

    def stop(self) -> None:
        if self.client is not None:
            self.client.close()
        order = [n for n in self.procs if n != "scheduler"] + ["scheduler"]
        for name in order:
            if self.procs.get(name) and self.procs[name].poll() is None:
                try:
                    os.killpg(self.procs[name].pid, signal.SIGTERM)
                except ProcessLookupError:
                    pass
        for name in order:
            proc = self.procs.get(name)
            if proc is None:
                continue
            try:
                proc.wait(10)
            except subprocess.TimeoutExpired:
                pass
            try:  # the group too: a nanny's worker process may outlive it
                os.killpg(proc.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
            proc.wait()


@pytest.fixture(scope="module")
def cluster(tmp_path_factory):
    c = Cluster(tmp_path_factory.mktemp("dask_cluster"))
    try:
        c.start()
        yield c
    finally:
        c.stop()


def _params(root: Path, name: str, **compute) -> Path:
    data = copy.deepcopy(TINY)
    data["compute"].update(compute)
    path = root / f"{name}.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def _run(stage, params: Path, data_root: Path, out: Path) -> tuple[Path, Path]:
    """Run ``stage`` reading ``data_root``, writing into ``out``/{data,reports}."""
    name = stage.__name__.rsplit(".", 1)[-1]
    data, rep = out / "data" / name, out / "reports" / name
    assert stage.main(["--params", str(params), "--data-root", str(data_root),
                       "--data-dir", str(data), "--reports-dir", str(rep)]) == 0
    return data, rep


@pytest.fixture(scope="module")
def local(tmp_path_factory):
    """mesh_gen and render_views on TINY with the local backend, one in-process worker."""
    root = tmp_path_factory.mktemp("local")
    params = _params(root, "local", backend="local", n_workers=1, scheduler_address=None)
    runs = {"mesh_gen": _run(mesh_gen, params, root / "data", root)}
    runs["render_views"] = _run(render_views, params, root / "data", root)
    return root / "data", runs


def assert_same_file(a: Path, b: Path) -> None:
    assert a.read_bytes() == b.read_bytes(), f"{a} and {b} differ"


def _assert_bar_done(err: str, desc: str, n: int) -> None:
    assert re.search(rf"{desc}: 100%\|[^|\n\r]*\| {n}/{n} ", err), (
        f"no finished '{desc}' progress bar ({n}/{n}) on stderr:\n{err[-2000:]}")


def test_dask_cluster_matches_local(local, cluster, tmp_path, capsys):
    """mesh_gen (workers write the meshes) and render_views (workers read them, write the
    clouds) on the two-worker cluster: every artifact byte-identical to the local run's."""
    def executed(dask_worker):  # nested: pickled by value, workers can't import this module
        return dask_worker.state.executed_count

    inputs, ref = local
    params = _params(tmp_path, "dask", backend="dask", n_workers=1,
                     scheduler_address=cluster.address)
    with cluster.logs_on_failure():
        cluster.ensure_workers(N_WORKERS)
        before = cluster.client.run(executed)
        capsys.readouterr()
        for stage, data_root in ((mesh_gen, tmp_path / "data"), (render_views, inputs)):
            name = stage.__name__.rsplit(".", 1)[-1]
            data, rep = _run(stage, params, data_root, tmp_path)
            assert_same_tree(ref[name][0], data)
            assert_same_file(ref[name][1] / "metrics.json", rep / "metrics.json")
        err = capsys.readouterr().err
        _assert_bar_done(err, "supports", TINY["mesh_gen"]["n_supports"])
        _assert_bar_done(err, "objects", 1 + 5 * TINY["mesh_gen"]["n_objects_per_category"])
        # the work was spread: each of the two worker processes ran tasks
        after = cluster.client.run(executed)
        assert len(after) == N_WORKERS and all(after[w] > before.get(w, 0) for w in after), (
            f"tasks executed per worker before {before}, after {after}")


class _Killer(threading.Thread):
    """Once the stage has written its first item, SIGKILLs (whole process group: nanny and
    worker) one worker that is processing a task, and records the state at that moment."""

    def __init__(self, cluster: Cluster, data: Path, metrics: Path):
        super().__init__(daemon=True)
        self.cluster, self.data, self.metrics = cluster, data, metrics
        self.procs = cluster.worker_procs()  # before the stage: the workers are idle
        self.stop = threading.Event()
        self.killed: str | None = None  # process name of the killed worker
        self.lost: list = []  # keys of the tasks it was processing
        self.n_done = -1  # items written when it was killed
        self.metrics_before = None  # had the stage written its metrics by then?
        self.error: BaseException | None = None

    def _done(self) -> int:
        return len(list(self.data.glob("support_*.npz")))

    def run(self):
        try:
            while not self.stop.is_set():
                if self._done() >= 1:
                    busy = {w: ks for w, ks in self.cluster.client.processing().items() if ks}
                    if busy:
                        worker = sorted(busy)[0]
                        self.lost = list(busy[worker])
                        self.metrics_before = self.metrics.exists()
                        self.cluster.kill(self.procs[worker])
                        self.killed, self.n_done = self.procs[worker], self._done()
                        return
                time.sleep(0.02)
        except BaseException as err:  # reported by the test
            self.error = err


def test_dask_worker_killed_mid_stage(local, cluster, tmp_path, capsys):
    """SIGKILL one of the two workers while render_views runs: the stage completes on the
    other one and writes the same bytes as the local backend."""
    inputs, ref = local
    params = _params(tmp_path, "dask", backend="dask", n_workers=1,
                     scheduler_address=cluster.address)
    n_items = TINY["mesh_gen"]["n_supports"]
    data, rep = tmp_path / "data" / "render_views", tmp_path / "reports" / "render_views"
    with cluster.logs_on_failure():
        cluster.ensure_workers(N_WORKERS)
        capsys.readouterr()
        killer = _Killer(cluster, data, rep / "metrics.json")
        killer.start()
        try:
            _run(render_views, params, inputs, tmp_path)
        finally:
            killer.stop.set()
            killer.join(30)
        err = capsys.readouterr().err
        assert killer.error is None, f"the killer thread failed: {killer.error!r}"
        assert killer.killed, "no worker was killed: the stage finished before the kill"
        assert not killer.metrics_before, "the worker was killed after the stage's items"
        assert killer.n_done < n_items and killer.lost, (
            f"the kill came too late: {killer.n_done}/{n_items} items were written, "
            f"tasks lost: {killer.lost}")
        assert len(cluster.client.scheduler_info(n_workers=-1)["workers"]) == N_WORKERS - 1
        # also no temp file of a write the kill interrupted (the stage removes them)
        assert_same_tree(ref["render_views"][0], data)
        assert_same_file(ref["render_views"][1] / "metrics.json", rep / "metrics.json")
        _assert_bar_done(err, "supports", n_items)
        print(f"killed {killer.killed} with {killer.n_done}/{n_items} items written, "
              f"{len(killer.lost)} task(s) lost")
