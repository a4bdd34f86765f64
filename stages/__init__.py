"""DVC stages: thin scripts that call skt_lib, log to Rerun and write reports."""
