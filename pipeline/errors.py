"""Typed errors of the pipeline package; each names the file, key or record and what to do."""

from __future__ import annotations

from navreplay.ingest.typed import KeyPathError


class PipelineError(Exception):
    """Base class for errors raised by the pipeline package."""


class ParamsError(KeyPathError, PipelineError):
    """A parameter file is malformed: unknown or misspelled key, wrong type, missing section.

    Carries ``key_path`` (e.g. ``run.filters[2]``), ``reason`` and ``source`` (the file).
    """


class NotBuiltError(PipelineError):
    """A capability the architecture names but this version does not implement yet."""


class DivergenceError(PipelineError):
    """A filter produced non-finite values or lost positive definiteness and could not recover."""
