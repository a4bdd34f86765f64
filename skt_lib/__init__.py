"""skt_lib: the SKT-Hang pipeline as a library.

Pure functions and a few resource classes; never prints, never imports rerun, dvclive,
matplotlib or tqdm. Stages under ``stages/`` and drawing under ``viz/`` build on it.
"""

__version__ = "0.1.0"
