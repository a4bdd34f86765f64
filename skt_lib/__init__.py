"""skt_lib: the SKT-Hang pipeline as a library.

Pure functions and a few resource classes. Below the command line (``skt_lib.cli``) it
never prints and never imports ``viz``, rerun, dvclive, matplotlib or tqdm; the command line
sits above ``viz``: it prints, shows tqdm progress bars and writes ``--rrd`` recordings
through ``viz``. Stages under ``stages/`` build on it all. The layer order is the
import-linter contract in ``pyproject.toml`` (docs/reproducibility.md, "Layout").
"""

__version__ = "0.1.0"
