"""Targets for :func:`skt_lib.isolated.call_isolated` that fail the ways native code does
(run in the child process by the decomposition tests)."""

import os
import time

import numpy as np


def abort(**_) -> dict:
    """What a failed C++ assertion does: SIGABRT."""
    os.abort()


def hang(**_) -> dict:
    time.sleep(600)
    return {}


def raise_error(**_) -> dict:
    raise ValueError("a library error")


def no_parts(vertices, faces, **_) -> dict:
    return {"points": np.zeros((0, 3)), "counts": np.zeros(0, dtype=np.int64)}


def echo(vertices, faces, scale: float, **_) -> dict:
    return {"vertices": vertices * scale, "faces": faces}
