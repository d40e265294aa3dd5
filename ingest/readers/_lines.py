"""Damage bookkeeping shared by the line-oriented text readers (CSV, NMEA, libRSF).

Lines are numbered from 1 and stand in for byte offsets (``LogReader.offsets_are_lines``).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

from navreplay.ingest.damage import Completeness, Defect

MAX_LISTED = 20  # line numbers named in a message; the rest are counted


def listed(lines: Sequence[int]) -> str:
    """``lines`` for a message: the first ``MAX_LISTED`` numbers, then how many more."""
    shown = ", ".join(str(n) for n in lines[:MAX_LISTED])
    more = len(lines) - MAX_LISTED
    return shown + (f" and {more} more" if more > 0 else "")


@dataclass
class BadLines:
    """The malformed lines skipped in a file, and the reason of the first."""

    lines: list[int] = field(default_factory=list)
    first: str = ""

    def add(self, number: int, reason: str) -> None:
        if not self.lines:
            self.first = f"line {number}: {reason}"
        self.lines.append(number)

    def defect(self) -> Defect:
        return Defect(
            Completeness.BAD_DATA_SKIPPED,
            f"{len(self.lines)} malformed lines skipped (lines {listed(self.lines)}; "
            f"first: {self.first})",
            offset=self.lines[0],
        )


def partial_line_defect(line: int) -> Defect:
    """The last line, ``line``, has no newline: a truncated write, dropped."""
    return Defect(
        Completeness.PARTIAL_RECORD_DROPPED,
        f"line {line} (the last) has no newline: a truncated write, dropped",
        offset=line,
    )
