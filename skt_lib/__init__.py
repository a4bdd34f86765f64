"""skt_lib: the SKT-Hang pipeline as a library.

Pure functions and a few resource classes. Below the command line (``skt_lib.cli``) it
never prints and never imports ``viz``, rerun, dvclive, matplotlib or tqdm; the command line
sits above ``viz``: it prints, shows tqdm progress bars and writes ``--rrd`` recordings
through ``viz``. Stages under ``stages/`` build on it all. The layer order is the
import-linter contract in ``pyproject.toml`` (docs/reproducibility.md, "Layout").
"""

import os as _os
import platform as _platform
import sys as _sys
import warnings as _warnings

__version__ = "0.1.0"

#: The OpenBLAS kernel every process of ours computes with, on x86-64. OpenBLAS picks a
#: kernel per CPU (SkylakeX on an Intel Xeon, Zen on an AMD EPYC), and small products round
#: differently under each: ``contact_sim`` made other contacts on an AMD EPYC than on an
#: Intel Xeon from the same code and seed (with this set to SkylakeX, the EPYC made the
#: Xeon's). Haswell's kernels (AVX2 + FMA) run on every x86-64 CPU of the last decade.
BLAS_CORETYPE = "Haswell"


#: Threads OpenBLAS computes with in every process of ours: one. Our stages run one process
#: per core (``compute.n_workers``), each of which would otherwise start a thread per core
#: for every product: on 2 cores the wall's RANSAC (``render_views``' depth-camera views)
#: took 85-250 ms a view that way against 22 ms on one thread. One thread also keeps each
#: product's order of operations the same on any machine, whatever its core count.
BLAS_THREADS = "1"


#: numpy's and torch's own SIMD loops, held at AVX2 on x86-64 whatever the CPU offers. Each
#: picks its loops when it loads: numpy its AVX-512 ones (``X86_V4`` and up: SVML's sin, cos,
#: arccos, exp round otherwise than the AVX2 build's), torch's ATen its AVX-512 kernels. On
#: 2026-12-07 an AMD EPYC without AVX-512 planned other SKTs in ``rrt_skts`` than the
#: committed run's AVX-512 machine from the same code, seed and inputs (docs/reproducibility.md).
#: On a CPU without AVX-512 these change nothing (``rrt_skts`` and ``train`` rerun under them
#: gave the same bytes there); with it they take that CPU's AVX2 paths. Not pinned: the
#: libraries torch calls for products: ``MKL_CBWR=AVX2`` with ``ONEDNN_MAX_CPU_ISA=AVX2``
#: changed the trained SCTDN even on that AVX2 machine (pinning them means retraining).
SIMD_PINS = {"NPY_DISABLE_CPU_FEATURES": "X86_V4 AVX512_ICL AVX512_SPR",
             "ATEN_CPU_CAPABILITY": "avx2"}


def _pin_blas() -> None:
    """Set ``OPENBLAS_CORETYPE``, ``OPENBLAS_NUM_THREADS`` and, on x86-64,
    :data:`SIMD_PINS` (each unless the environment sets it) before numpy and torch load,
    which read them once. Importing ``skt_lib`` first does it (``stages`` and the ``skt``
    command do); where numpy came first, it is too late: a warning says so."""
    pins = {"OPENBLAS_NUM_THREADS": BLAS_THREADS}
    if _platform.machine().lower() in ("x86_64", "amd64"):
        pins |= {"OPENBLAS_CORETYPE": BLAS_CORETYPE, **SIMD_PINS}
    pins = {k: v for k, v in pins.items() if k not in _os.environ}
    if not pins:
        return
    _os.environ.update(pins)
    if "numpy" in _sys.modules:
        _warnings.warn("numpy was imported before skt_lib: its OpenBLAS kernel, thread "
                       f"count and SIMD loops are not ours ({pins}), so results may differ "
                       f"from other machines' in the last bits and products run slower; set "
                       + " ".join(f"{k}={v}" for k, v in pins.items()) + " or import skt_lib first",
                       RuntimeWarning, stacklevel=2)


_pin_blas()
