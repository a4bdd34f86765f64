"""One OpenBLAS kernel on every x86-64 CPU (``skt_lib.BLAS_CORETYPE``): a stage process
computes with it whatever kernel the CPU would pick, so machines agree (an AMD EPYC and an
Intel Xeon made other contacts in ``contact_sim`` from the same seed before); and on one
OpenBLAS thread (``skt_lib.BLAS_THREADS``), whatever the core count."""

import os
import platform
import subprocess
import sys
from pathlib import Path

import pytest

import skt_lib

ROOT = Path(__file__).resolve().parents[1]
pytestmark = pytest.mark.skipif(platform.machine().lower() not in ("x86_64", "amd64"),
                                reason="OpenBLAS core types pinned on x86-64 only")
CORENAME = """
import ctypes, glob, os, numpy
lib = glob.glob(os.path.join(os.path.dirname(numpy.__file__), "..", "numpy.libs",
                             "libscipy_openblas64*.so"))[0]
get = ctypes.CDLL(lib).scipy_openblas_get_corename64_
get.restype = ctypes.c_char_p
print(get().decode())
"""
THREADS = """
import ctypes, glob, os, numpy
lib = glob.glob(os.path.join(os.path.dirname(numpy.__file__), "..", "numpy.libs",
                             "libscipy_openblas64*.so"))[0]
print(ctypes.CDLL(lib).scipy_openblas_get_num_threads64_())
"""


def _run(code: str, **env) -> subprocess.CompletedProcess:
    clean = {k: v for k, v in os.environ.items()
             if k not in ("OPENBLAS_CORETYPE", "OPENBLAS_NUM_THREADS")}
    return subprocess.run([sys.executable, "-W", "always", "-c", code], cwd=ROOT,
                          env=clean | env, capture_output=True, text=True, check=True)


def test_a_stage_process_computes_with_the_pinned_kernel():
    assert _run("import stages" + CORENAME).stdout.strip() == skt_lib.BLAS_CORETYPE


def test_a_stage_process_computes_on_one_blas_thread():
    assert _run("import stages" + THREADS).stdout.strip() == skt_lib.BLAS_THREADS == "1"
    # without the pin OpenBLAS takes a thread per core (this check needs two or more)
    if os.cpu_count() > 1:
        assert _run("import numpy\nimport skt_lib" + THREADS).stdout.strip() != "1"


def test_the_environment_overrides_the_pin():
    out = _run("import stages" + CORENAME, OPENBLAS_CORETYPE="Sandybridge")
    assert out.stdout.strip() == "Sandybridge"
    assert _run("import stages" + THREADS, OPENBLAS_NUM_THREADS="2").stdout.strip() == "2"


def test_numpy_loaded_first_is_warned_about():
    out = _run("import numpy\nimport skt_lib")
    assert "numpy was imported before skt_lib" in out.stderr
    assert "numpy was imported before skt_lib" not in _run("import skt_lib\nimport numpy").stderr


SIMD = """
import os, numpy, torch
from numpy._core._multiarray_umath import __cpu_features__ as f
print(os.environ.get("NPY_DISABLE_CPU_FEATURES"), torch.backends.cpu.get_cpu_capability(),
      any(f[k] for k in ("X86_V4", "AVX512_ICL", "AVX512_SPR")))
"""


def _simd_clean(code: str, **env) -> list[str]:
    """``code``'s output (split) in a fresh interpreter whose environment has none of our
    pins but ``env``."""
    clean = {k: v for k, v in os.environ.items() if k not in skt_lib.SIMD_PINS
             and k not in ("OPENBLAS_CORETYPE", "OPENBLAS_NUM_THREADS")}
    return subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=clean | env,
                          capture_output=True, text=True, check=True).stdout.split()


def test_a_stage_process_runs_numpy_and_torch_on_their_avx2_paths():
    """On an AVX-512 CPU numpy and torch would take their AVX-512 loops (other roundings:
    other SKTs); a stage process takes the AVX2 ones on any x86-64 CPU with AVX2."""
    out = _simd_clean("import stages" + SIMD)
    disabled, torch_isa, avx512 = " ".join(out[:-2]), out[-2], out[-1]
    assert disabled == skt_lib.SIMD_PINS["NPY_DISABLE_CPU_FEATURES"]
    assert avx512 == "False"  # numpy: no AVX-512 loop is dispatched
    assert torch_isa in ("AVX2", "DEFAULT")  # DEFAULT: a CPU without AVX2 at all
    # an explicit setting wins, as for OpenBLAS
    out = _simd_clean("import stages" + SIMD, ATEN_CPU_CAPABILITY="default")
    assert out[-2] == "DEFAULT"
