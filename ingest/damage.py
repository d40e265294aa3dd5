"""The damage log of one input file: its recoverable defects and how complete its data is.

Every reader records into one (``ReadContext.damage``; ``ingest.readers.base`` says how), and
so do the RINEX parsers the readers use (``rinexobs``, ``rinexnav``, ``rinexepochs``);
``to_json`` is the file's entry in the ingest report.
"""

from __future__ import annotations

import logging
from dataclasses import dataclass
from enum import StrEnum
from pathlib import Path
from typing import Any

from navreplay.ingest.errors import CorruptLogError

log = logging.getLogger(__name__)


class Completeness(StrEnum):
    """How complete the data read from one file is (a file can carry several flags)."""

    COMPLETE = "complete"
    TRUNCATED = "truncated"
    CORRUPT_CHUNKS_SKIPPED = "corrupt_chunks_skipped"
    CORRUPT_TAIL = "corrupt_tail"
    NO_SUMMARY = "no_summary"
    UNINDEXED = "unindexed"
    BAD_DATA_SKIPPED = "bad_data_skipped"
    PARTIAL_RECORD_DROPPED = "partial_record_dropped"
    MISSING_METADATA = "missing_metadata"
    CHECKSUM_MISMATCH = "checksum_mismatch"
    DUPLICATED_COPY_DROPPED = "duplicated_copy_dropped"
    IMPLAUSIBLE_VALUES = "implausible_values"


@dataclass(frozen=True)
class Defect:
    """One recoverable defect of a file and what was done about it.

    Attributes:
        kind: the completeness flag it sets.
        reason: what is wrong and what was done, in one sentence.
        offset: byte offset in the file where it starts (or the line number for text files).
        messages_lost: messages known to be lost (from an index), if known.
        messages_recovered: messages recovered despite it (e.g. from a partial chunk).
        time_range_ns: log-time range affected, if known.
        bytes_skipped: bytes skipped, if known.
    """

    kind: Completeness
    reason: str
    offset: int | None = None
    messages_lost: int | None = None
    messages_recovered: int | None = None
    time_range_ns: tuple[int, int] | None = None
    bytes_skipped: int | None = None


class DamageLog:
    """Collects the defects of one file; under ``strict`` the first defect is an error.

    Args:
        path: the file the defects belong to.
        strict: raise ``CorruptLogError`` on ``record`` instead of collecting.
    """

    def __init__(self, path: Path, *, strict: bool) -> None:
        self.path = path
        self.strict = strict
        self.offsets_are_lines = False  # text readers report line numbers as offsets
        self.defects: list[Defect] = []
        self.notes: list[str] = []
        self.counters: dict[str, int] = {}

    def record(self, defect: Defect) -> None:
        """Record a recoverable defect; raises ``CorruptLogError`` under ``--strict``."""
        if self.strict:
            line = self.offsets_are_lines and defect.offset is not None
            raise CorruptLogError(
                f"{defect.reason} [{defect.kind.value}]",
                path=self.path,
                offset=None if line else defect.offset,
                record=f"line {defect.offset}" if line else None,
                hint="--strict refuses recoverable defects; rerun without it to salvage what "
                "is readable",
            )
        log.warning("%s: %s", self.path, defect.reason)
        self.defects.append(defect)

    def note(self, text: str) -> None:
        """A remark for the report that is not a defect (e.g. "CRC checks on")."""
        self.notes.append(text)

    def count(self, name: str, n: int = 1) -> None:
        self.counters[name] = self.counters.get(name, 0) + n

    @property
    def completeness(self) -> list[str]:
        kinds = sorted({d.kind.value for d in self.defects})
        return kinds or [Completeness.COMPLETE.value]

    def to_json(self) -> dict[str, Any]:
        return {
            "completeness": self.completeness,
            "defects": [
                {k: v for k, v in d.__dict__.items() if v is not None} for d in self.defects
            ],
            "notes": list(self.notes),
            "counters": dict(sorted(self.counters.items())),
        }
