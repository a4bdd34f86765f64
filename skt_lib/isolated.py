"""Run a function in a child process, so that native code cannot take the caller down.

Native libraries abort on some inputs (CoACD: ``Assertion 'd0 != d2' failed``, SIGABRT) or
run for ever; in-process either ends the ``skt`` command with no ``ERROR:`` line. Here the
function ``module:name`` runs in ``python -m skt_lib.isolated`` with its arrays passed
through an ``.npz`` file, under a time limit; an abort, a crash, a non-zero exit or a
timeout becomes :class:`ChildFailed` saying which. The child dies with its parent (Linux
``PR_SET_PDEATHSIG``), so a killed import leaves no orphan computing on.

The function takes numpy arrays and JSON-able options as keyword arguments and returns a
dict of numpy arrays.
"""

import ctypes
import functools
import importlib
import json
import os
import signal
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np

from skt_lib.errors import SktError

_PR_SET_PDEATHSIG = 1


class ChildFailed(SktError):
    """The isolated call did not return: aborted, crashed, raised, or ran out of time."""


def _die_with_parent(parent: int) -> None:  # pragma: no cover - runs in the child before exec
    """Ask for SIGKILL when the parent dies; and where ``parent`` (the caller's pid) died
    already — between the fork and this call, a window a loaded machine widens — die now: the
    pledge would name the new parent, who never dies, and the child would compute on."""
    try:
        ctypes.CDLL("libc.so.6", use_errno=True).prctl(_PR_SET_PDEATHSIG, signal.SIGKILL)
    except OSError:
        return  # not Linux: the child may outlive a killed parent
    if os.getppid() != parent:
        os.kill(os.getpid(), signal.SIGKILL)


def _last_line(text: str) -> str:
    lines = [ln.strip() for ln in text.splitlines() if ln.strip()]
    return lines[-1][:200] if lines else ""


def call_isolated(target: str, arrays: dict[str, np.ndarray], options: dict | None = None,
                  time_limit_s: float = 120.0) -> dict[str, np.ndarray]:
    """``module:function(**arrays, **options)`` in a child process; its returned arrays, or
    :class:`ChildFailed` naming how it ended."""
    with tempfile.TemporaryDirectory(prefix="skt-isolated-") as tmp:
        src, dst = Path(tmp) / "in.npz", Path(tmp) / "out.npz"
        np.savez(src, __options__=np.array(json.dumps(options or {})), **arrays)
        try:
            proc = subprocess.run([sys.executable, "-m", "skt_lib.isolated", target, str(src),
                                   str(dst)], capture_output=True, text=True,
                                  timeout=time_limit_s,
                                  preexec_fn=functools.partial(_die_with_parent, os.getpid()))
        except subprocess.TimeoutExpired:
            raise ChildFailed(f"no result within {time_limit_s:g} s (stopped)") from None
        if proc.returncode < 0:
            name = signal.Signals(-proc.returncode).name
            detail = _last_line(proc.stderr)
            raise ChildFailed(f"the process ended by {name}" + (f" ({detail})" if detail else ""))
        if proc.returncode != 0 or not dst.is_file():
            raise ChildFailed(f"exit code {proc.returncode}: {_last_line(proc.stderr)}")
        with np.load(dst) as out:
            return {k: out[k] for k in out.files}


def _child(target: str, src: str, dst: str) -> int:
    module, name = target.split(":")
    fn = getattr(importlib.import_module(module), name)
    with np.load(src) as data:
        options = json.loads(str(data["__options__"]))
        arrays = {k: data[k] for k in data.files if k != "__options__"}
    out = fn(**arrays, **options)
    np.savez(dst, **out)
    return 0


if __name__ == "__main__":
    sys.exit(_child(*sys.argv[1:4]))
