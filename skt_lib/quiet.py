"""Native libraries that print when imported, made to print nowhere.

PyBullet's C extension prints ``pybullet build time: …`` with ``printf`` when it is first
imported (to stderr with this build; a user saw it before ``skt``'s own output). A command
line tool's streams are its interface: ``skt`` writes its result on stdout and one
``ERROR:`` line on stderr, nothing else. :func:`import_quietly` imports a module with file
descriptors 1 and 2 pointed at ``/dev/null`` (``to_stderr``: both at stderr), flushing C's
stdio buffers before pointing them back; Python-level redirection
(``contextlib.redirect_stdout``) does not reach ``printf``.
"""

import ctypes
import importlib
import os
import sys


def import_quietly(module: str, to_stderr: bool = False):
    """``importlib.import_module(module)`` with what it prints sent to nowhere
    (``to_stderr``: to stderr, never stdout). Already imported: returned as it is."""
    if module in sys.modules:
        return sys.modules[module]
    sys.stdout.flush()
    sys.stderr.flush()
    libc = ctypes.CDLL(None)
    saved = [os.dup(1), os.dup(2)]
    target = os.dup(2) if to_stderr else os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(target, 1)
        os.dup2(target, 2)
        return importlib.import_module(module)
    finally:
        libc.fflush(None)
        for fd, copy in zip((1, 2), saved):
            os.dup2(copy, fd)
            os.close(copy)
        os.close(target)
