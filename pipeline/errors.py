"""Typed errors of the pipeline package; each names the file, key or record and what to do."""

from __future__ import annotations


class PipelineError(Exception):
    """Base class for errors raised by the pipeline package."""


class ParamsError(PipelineError):
    """A parameter file is malformed: unknown or misspelled key, wrong type, missing section.

    Args:
        key_path: dotted path of the offending key, e.g. ``run.filters[2]``.
        reason: what is wrong.
        source: the parameter file, if known.
    """

    def __init__(self, key_path: str, reason: str, *, source: str | None = None) -> None:
        self.key_path = key_path
        self.reason = reason
        self.source = source
        where = f"{source}: " if source else ""
        super().__init__(f"{where}{key_path or '<top level>'}: {reason}")


class NotBuiltError(PipelineError):
    """A capability the architecture names but this version does not implement yet."""


class DivergenceError(PipelineError):
    """A filter produced non-finite values or lost positive definiteness and could not recover."""
