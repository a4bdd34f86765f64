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


def _pin_blas() -> None:
    """Set ``OPENBLAS_CORETYPE`` and ``OPENBLAS_NUM_THREADS`` (each unless the environment
    sets it) before numpy loads OpenBLAS, which reads them once. Importing ``skt_lib`` first
    does it (``stages`` and the ``skt`` command do); where numpy came first, it is too late:
    a warning says so."""
    pins = {"OPENBLAS_NUM_THREADS": BLAS_THREADS}
    if _platform.machine().lower() in ("x86_64", "amd64"):
        pins["OPENBLAS_CORETYPE"] = BLAS_CORETYPE
    pins = {k: v for k, v in pins.items() if k not in _os.environ}
    if not pins:
        return
    _os.environ.update(pins)
    if "numpy" in _sys.modules:
        _warnings.warn("numpy was imported before skt_lib: its OpenBLAS kernel and thread "
                       f"count are not ours ({pins}), so results may differ from other "
                       f"machines' in the last bits and products run slower; set "
                       + " ".join(f"{k}={v}" for k, v in pins.items()) + " or import skt_lib first",
                       RuntimeWarning, stacklevel=2)


_pin_blas()
