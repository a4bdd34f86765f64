"""DVC stages: thin scripts that call skt_lib, log to Rerun and write reports."""

import skt_lib  # noqa: E402,F401  (first: it pins the BLAS kernel before numpy loads)
