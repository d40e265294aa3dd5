"""Field checks of the filters' typed parameter sections."""

from __future__ import annotations

from navreplay.ingest.typed import FieldError


def _positive(obj: object, *names: str, allow_zero: bool = False) -> None:
    for name in names:
        value = getattr(obj, name)
        if not (value >= 0 if allow_zero else value > 0):
            raise FieldError(name, "must be >= 0" if allow_zero else "must be > 0")
