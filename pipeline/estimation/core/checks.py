"""Field checks of the filters' typed parameter sections."""

from __future__ import annotations

from navreplay.ingest.typed import FieldError


def positive(obj: object, *names: str, allow_zero: bool = False) -> None:
    """Raise ``FieldError`` for the first of the fields ``names`` of ``obj`` that is not > 0
    (>= 0 with ``allow_zero``)."""
    for name in names:
        value = getattr(obj, name)
        if not (value >= 0 if allow_zero else value > 0):
            raise FieldError(name, "must be >= 0" if allow_zero else "must be > 0")
