"""Typed errors of the ingest package.

Every error names the file, and where it applies the byte offset, record or column, the
reason, and what the user can do about it. Errors raised by third-party readers are re-raised
at this boundary as one of these classes, chained with ``from err``.
"""

from __future__ import annotations

from pathlib import Path


class IngestError(Exception):
    """Base class for every error the ingest package raises.

    Args:
        reason: what is wrong, in one sentence.
        path: the file concerned, if any.
        offset: byte offset in the file, if known.
        record: the record, message, topic, line or row concerned, if known.
        hint: what the user can do about it.
    """

    def __init__(
        self,
        reason: str,
        *,
        path: str | Path | None = None,
        offset: int | None = None,
        record: str | None = None,
        hint: str | None = None,
    ) -> None:
        self.reason = reason
        self.path = Path(path) if path is not None else None
        self.offset = offset
        self.record = record
        self.hint = hint
        super().__init__(self._format())

    def _format(self) -> str:
        where = []
        if self.path is not None:
            where.append(str(self.path))
        if self.offset is not None:
            where.append(f"offset {self.offset}")
        if self.record is not None:
            where.append(self.record)
        text = f"{': '.join(where)}: {self.reason}" if where else self.reason
        if self.hint:
            text += f" ({self.hint})"
        return text


class UnsupportedFormatError(IngestError):
    """The file is empty, not a log, or a format navreplay does not read."""


class CorruptLogError(IngestError):
    """The log is damaged beyond what can be recovered, or damaged and ``--strict`` is set."""


class TableValidationError(IngestError):
    """A table does not satisfy its canonical schema.

    Args:
        table: canonical table name (``imu``, ``gnss`` ...).
        column: the offending column, if one is to blame.
        row: index of the first offending row, if one is to blame.
    """

    def __init__(
        self,
        reason: str,
        *,
        table: str,
        column: str | None = None,
        row: int | None = None,
        path: str | Path | None = None,
        hint: str | None = None,
    ) -> None:
        self.table = table
        self.column = column
        self.row = row
        parts = [f"table {table!r}"]
        if column is not None:
            parts.append(f"column {column!r}")
        if row is not None:
            parts.append(f"row {row}")
        super().__init__(reason, path=path, record=", ".join(parts), hint=hint)


class ProvenanceError(IngestError):
    """A Parquet file lacks navreplay provenance, or it does not match what the reader expects."""


class PlausibilityError(IngestError):
    """Values fail a physical plausibility check (units, frames, ranges)."""


class ConfigError(IngestError):
    """A dataset descriptor (``dataset.yaml``) is malformed."""


class OutputPathError(IngestError):
    """The output path cannot be written without destroying something navreplay did not write."""
