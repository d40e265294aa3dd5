"""The block loop shared by the tlog and DataFlash scans, and the damage both report.

Both logs are read in blocks: a block is the tail carried over from the previous one (a
record cut by the block end) followed by fresh bytes; a scan of it reports how far it got
(``stop``), a garbage run still open at its end, and on the last block whether the file ends
inside a record.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import TypeVar

import numpy as np

from navreplay.ingest.arrays import I64, U8
from navreplay.ingest.damage import Completeness, DamageLog, Defect
from navreplay.ingest.readers.mavlink._mavscan import END_PARTIAL, partial_record_defect

MAX_LISTED = 20  # garbage runs named (offset, length) in the defect; the rest are counted

T = TypeVar("T")

#: ``scan(buf, base, final, garbage)`` -> ``(records or None, stop, garbage, end_status)``:
#: ``buf`` starts at file offset ``base``; ``garbage`` is the open garbage run's start (-1).
BlockScan = Callable[[U8, int, bool, int], tuple[T | None, int, int, int]]


@dataclass
class BlockStats:
    """Garbage runs and a trailing partial record found by one scan of a file."""

    garbage_runs: int = 0
    garbage_bytes: int = 0
    garbage_listed: list[tuple[int, int]] = field(default_factory=list)
    partial_offset: int | None = None
    partial_bytes: int = 0
    last_run: tuple[int, int] | None = None

    def add_gaps(self, gap_pos: I64, gap_len: I64) -> None:
        """Count the garbage runs at ``gap_pos`` (absolute offsets) of ``gap_len`` bytes."""
        for at, length in zip(gap_pos.tolist(), gap_len.tolist(), strict=True):
            self.garbage_runs += 1
            self.garbage_bytes += length
            if len(self.garbage_listed) < MAX_LISTED:
                self.garbage_listed.append((at, length))
            self.last_run = (at, length)

    def trailing_header(self, path: Path, header: bytes) -> None:
        """A last garbage run that ends the file and is a prefix of a record ``header`` is a
        record cut inside its header (the scan could not know its type): a partial record."""
        if self.last_run is None or self.partial_offset is not None:
            return
        at, n = self.last_run
        if n >= len(header) or at + n != path.stat().st_size:
            return
        with path.open("rb") as fh:
            fh.seek(at)
            if fh.read(n) != header[:n]:
                return
        self.garbage_runs -= 1
        self.garbage_bytes -= n
        if self.garbage_listed and self.garbage_listed[-1] == (at, n):
            self.garbage_listed.pop()
        self.last_run = None
        self.partial_offset, self.partial_bytes = at, n

    def record_garbage(self, dmg: DamageLog, what: str, how: str = "") -> None:
        """Report the garbage runs, bytes that are not ``what``, skipped (``how``)."""
        if not self.garbage_runs:
            return
        dmg.count("garbage_runs", self.garbage_runs)
        dmg.count("garbage_bytes", self.garbage_bytes)
        listed = ", ".join(f"{at} (+{n})" for at, n in self.garbage_listed)
        dmg.record(
            Defect(
                Completeness.BAD_DATA_SKIPPED,
                f"{self.garbage_runs} runs of bytes that are not {what} "
                f"({self.garbage_bytes} bytes) skipped{how}; at offsets {listed}",
                offset=self.garbage_listed[0][0],
                bytes_skipped=self.garbage_bytes,
            )
        )

    def record_partial(self, dmg: DamageLog) -> None:
        """Report the trailing partial record, if the file ends inside one."""
        if self.partial_offset is not None:
            dmg.record(partial_record_defect(self.partial_offset, self.partial_bytes))


def scan_file(path: Path, block_bytes: int, stats: BlockStats, scan: BlockScan[T]) -> Iterator[T]:
    """Run ``scan`` over ``path`` block by block; yield what it finds in each block."""
    size = path.stat().st_size
    base = 0
    garbage = -1
    carry = np.empty(0, np.uint8)
    with path.open("rb") as fh:
        while True:
            fresh = np.frombuffer(fh.read(block_bytes), np.uint8)
            buf = np.concatenate([carry, fresh]) if len(carry) else fresh
            final = base + len(buf) >= size
            found, stop, garbage, end = scan(buf, base, final, garbage)
            if found is not None:
                yield found
            if final:
                if end == END_PARTIAL:
                    stats.partial_offset = base + stop
                    stats.partial_bytes = len(buf) - stop
                return
            carry = buf[stop:].copy()
            base += stop
