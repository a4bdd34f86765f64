"""Convex decomposition that native code cannot take down: each route in a child process
(:mod:`skt_lib.isolated`), an abort, a hang or an error there is the next route's turn,
and only when every route fails is the mesh refused, naming each."""

import os
import signal
import time

import numpy as np
import pytest
import trimesh

from skt_lib.cli.mesh_zoo import knob_peg, two_bodies
from skt_lib.errors import MeshError
from skt_lib.geometry.checks import check_parts
from skt_lib.geometry.convex import Mesh
from skt_lib.geometry.decompose import ROUTES, Route, decompose
from skt_lib.isolated import ChildFailed, call_isolated

FAULTS = "tests.geometry.faults"


def _mesh(tm: trimesh.Trimesh) -> Mesh:
    return Mesh(np.asarray(tm.vertices, float), np.asarray(tm.faces, np.int64))


@pytest.fixture(scope="module")
def peg() -> Mesh:
    return _mesh(knob_peg())


def test_a_child_returns_its_arrays():
    v = np.arange(12.0).reshape(4, 3)
    out = call_isolated(f"{FAULTS}:echo", {"vertices": v, "faces": np.array([[0, 1, 2]])},
                        {"scale": 2.0}, time_limit_s=60)
    np.testing.assert_array_equal(out["vertices"], 2 * v)
    np.testing.assert_array_equal(out["faces"], [[0, 1, 2]])


@pytest.mark.parametrize("target, said", [
    ("abort", "ended by SIGABRT"),
    ("raise_error", "exit code 1: ValueError: a library error"),
])
def test_a_crash_in_the_child_is_an_error_here(target, said):
    with pytest.raises(ChildFailed, match=said):
        call_isolated(f"{FAULTS}:{target}", {"vertices": np.zeros((1, 3))}, time_limit_s=60)


def test_a_child_past_its_time_limit_is_stopped():
    t0 = time.perf_counter()
    with pytest.raises(ChildFailed, match="no result within 2 s"):
        call_isolated(f"{FAULTS}:hang", {"vertices": np.zeros((1, 3))}, time_limit_s=2)
    assert time.perf_counter() - t0 < 10


def test_an_aborting_route_falls_back_to_the_next(peg):
    routes = (Route("coacd_abort", f"{FAULTS}:abort"), Route("hangs", f"{FAULTS}:hang"),
              ROUTES[-1])
    parts, route = decompose(peg, routes=routes, time_limit_s=20)
    assert route == "vhacd"
    assert check_parts(parts, peg, "peg", min_iou=0.85) >= 0.85  # V-HACD's parts, convex


def test_every_route_failing_is_one_error_naming_each(peg):
    routes = (Route("first", f"{FAULTS}:abort"), Route("second", f"{FAULTS}:raise_error"),
              Route("third", f"{FAULTS}:no_parts"))
    with pytest.raises(MeshError) as err:
        decompose(peg, routes=routes, time_limit_s=20)
    msg = str(err.value)
    assert "first: the process ended by SIGABRT" in msg
    assert "second: exit code 1: ValueError: a library error" in msg
    assert "third: no parts" in msg


def test_coacd_without_its_remesher_keeps_a_union_of_bodies_tight():
    """Two overlapping bodies, united by repair: CoACD's own manifold check calls the exact
    union's slivers self-intersections and, left on, voxelizes it 1 mm fat (IoU 0.82)."""
    from skt_lib.geometry.repair import repair

    mesh = repair(_mesh(two_bodies()), "two bodies")
    parts, route = decompose(mesh)
    assert route == "coacd"
    assert check_parts(parts, mesh, "two bodies", min_iou=0.95) >= 0.95


def test_a_killed_caller_takes_its_child_with_it(tmp_path):
    """The child dies with its parent (PR_SET_PDEATHSIG): a killed import leaves nothing
    computing on."""
    import subprocess
    import sys

    script = tmp_path / "parent.py"
    script.write_text(
        "import numpy as np\n"
        "from skt_lib.isolated import call_isolated\n"
        f"call_isolated('{FAULTS}:hang', {{'vertices': np.zeros((1, 3))}}, time_limit_s=600)\n")
    parent = subprocess.Popen([sys.executable, str(script)], cwd=os.getcwd())
    child = None
    for _ in range(200):
        child = _children(parent.pid)
        if child:
            break
        time.sleep(0.05)
    assert child, "the child never started"
    os.kill(parent.pid, signal.SIGKILL)
    parent.wait()
    for _ in range(100):
        if not os.path.exists(f"/proc/{child[0]}") or _state(child[0]) == "Z":
            break
        time.sleep(0.05)
    else:
        pytest.fail(f"child {child[0]} outlived its killed parent")


def _children(pid: int) -> list[int]:
    with open(f"/proc/{pid}/task/{pid}/children") as f:
        return [int(c) for c in f.read().split()]


def _state(pid: int) -> str:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0]
    except FileNotFoundError:
        return "gone"


def test_a_child_whose_caller_died_before_its_pledge_dies_at_once():
    """The race the pledge leaves open: the caller killed between the fork and the child's
    PR_SET_PDEATHSIG. The child then finds another parent than its caller's pid and ends
    itself rather than computing on (it cannot be signalled by a parent already gone)."""
    import subprocess
    import sys

    code = ("import os\nfrom skt_lib.isolated import _die_with_parent\n"
            "_die_with_parent({parent})\nprint('computing on')\n")
    gone = subprocess.run([sys.executable, "-c", code.format(parent=1)], capture_output=True,
                          text=True)  # pid 1 is not its parent: the caller is "gone"
    assert gone.returncode == -signal.SIGKILL and "computing on" not in gone.stdout
    alive = subprocess.run([sys.executable, "-c", code.format(parent=os.getpid())],
                           capture_output=True, text=True)  # this process is its parent
    assert alive.returncode == 0 and "computing on" in alive.stdout
