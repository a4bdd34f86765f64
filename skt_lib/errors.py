"""Typed errors. Expected per-item failures subclass :class:`ItemFailure` and carry a
short machine-readable ``reason`` that stages count into ``metrics.json``."""


class SktError(Exception):
    """Base class of every error this project raises on purpose."""


class ParamsError(SktError, ValueError):
    """params.yaml is missing a key, has an unknown key, or a value out of range."""


class DataError(SktError, ValueError):
    """An artifact on disk is missing, malformed or has the wrong schema."""


class MeshError(SktError, ValueError):
    """A mesh is broken: not watertight, non-positive volume, wrong units, non-convex part."""


class ItemFailure(SktError):
    """An expected failure of one item (one support, one object, one trial)."""

    reason = "failed"

    def __init__(self, message: str, reason: str | None = None):
        super().__init__(message)
        if reason is not None:
            self.reason = reason


class GenerationFailed(ItemFailure):
    """A procedural shape could not be generated with the requested properties."""

    reason = "generation_failed"


class InputError(SktError, ValueError):
    """A file or argument given on the command line is missing, unreadable or wrong."""
