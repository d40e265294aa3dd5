"""One rule over many fields of a synthesizer's parameter dataclass (noise, masses, variances)."""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

from navreplay.ingest.typed import FieldError


def _names(params: Any, names: Iterable[str] | None) -> Iterable[str]:
    return params.__dataclass_fields__ if names is None else names


def require_positive(params: Any, names: Iterable[str] | None = None) -> None:
    """Raise ``FieldError(name, "must be > 0")`` for the first of ``names`` (default: every
    field of the dataclass ``params``) whose value is <= 0."""
    for name in _names(params, names):
        if getattr(params, name) <= 0:
            raise FieldError(name, "must be > 0")


def require_non_negative(
    params: Any, names: Iterable[str] | None = None, *, message: str = "must be >= 0"
) -> None:
    """Raise ``FieldError(name, message)`` for the first of ``names`` (default: every field of
    the dataclass ``params``) whose value is a number < 0 (fields of other types are not
    checked)."""
    for name in _names(params, names):
        value = getattr(params, name)
        if isinstance(value, int | float) and not isinstance(value, bool) and value < 0:
            raise FieldError(name, message)
