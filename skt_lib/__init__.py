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


def _pin_blas_kernel() -> None:
    """Set ``OPENBLAS_CORETYPE`` (unless the environment sets it) before numpy loads
    OpenBLAS, which reads it once. Importing ``skt_lib`` first does it (``stages`` and the
    ``skt`` command do); where numpy came first, it is too late: a warning says so."""
    if _platform.machine().lower() not in ("x86_64", "amd64") or "OPENBLAS_CORETYPE" in _os.environ:
        return
    _os.environ["OPENBLAS_CORETYPE"] = BLAS_CORETYPE
    if "numpy" in _sys.modules:
        _warnings.warn("numpy was imported before skt_lib: its OpenBLAS kernel is the CPU's "
                       f"own, not {BLAS_CORETYPE}, so results may differ from other machines' "
                       f"in the last bits; set OPENBLAS_CORETYPE={BLAS_CORETYPE} or import "
                       "skt_lib first", RuntimeWarning, stacklevel=2)


_pin_blas_kernel()
