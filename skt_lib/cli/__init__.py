"""The ``skt`` console script: predict on a user's cloud, import a user's hook or object,
hang an object and record the rollout. A thin layer like ``stages/``: parse, call
``skt_lib``, print. Expected errors are one ``ERROR:`` line and exit code 2."""

import sys

from skt_lib.quiet import import_quietly

# before any command module imports it: PyBullet's banner goes to nowhere (stderr with --debug)
import_quietly("pybullet", to_stderr="--debug" in sys.argv)
