"""One pass over an ArduPilot DataFlash log in blocks: records as arrays, formats as they come.

``scan_blocks`` frames each block with the compiled ``scan_dataflash`` (record lengths from the
FMT records seen so far, carried across blocks) and yields ``Records``: file offset, position
in the block and type of every record. ``Formats`` follows the FMT records in file order (an
FMT may appear anywhere: ArduPilot writes most formats lazily before first use) and tells the
decoder which format applies to which records; an FMT it cannot use (an unknown format
character: catalogue case 17) is remembered with its offset, so that a reader needing that
type can fail naming it. ``ScanStats`` keeps the damage: garbage runs (offsets, bytes) and a
trailing partial record.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from navreplay.ingest.arrays import I64, U8
from navreplay.ingest.readers.mavlink._blocks import BlockStats, scan_file
from navreplay.ingest.readers.mavlink._mavscan import gather, scan_dataflash
from navreplay.ingest.readers.mavlink.dfformat import (
    FMT_FORMAT,
    FMT_LENGTH,
    FMT_TYPE,
    HEADER,
    DfFormat,
    FormatError,
    make_format,
    parse_fmt,
)

BLOCK_BYTES = 8 << 20

_EMPTY = np.empty(0, np.int64)


@dataclass
class Records:
    """The records of one block."""

    buf: U8
    pos: I64  # record start in buf
    offset: I64  # record start in the file
    type: U8
    _groups: dict[int, I64] | None = field(default=None, repr=False)

    def __len__(self) -> int:
        return len(self.pos)

    def of_type(self, type_: int) -> I64:
        """Indices of the records of ``type_``, in file order (one sort per block)."""
        if self._groups is None:
            order = np.argsort(self.type, kind="stable")
            counts = np.bincount(self.type, minlength=256)
            ends = np.cumsum(counts)
            self._groups = {
                int(t): order[ends[t] - counts[t] : ends[t]] for t in np.flatnonzero(counts)
            }
        return self._groups.get(type_, _EMPTY)

    def types(self) -> list[int]:
        self.of_type(0)
        assert self._groups is not None
        return sorted(self._groups)

    def column(self, idx: npt.NDArray[np.intp], fmt: DfFormat, name: str) -> np.ndarray:
        """One column of records ``idx`` (all of ``fmt``), without decoding the others."""
        fields: Mapping[str, Any] = fmt.dtype.fields or {}
        dtype, at = fields[name][:2]
        out = np.empty((len(idx), dtype.itemsize), np.uint8)
        gather(self.buf, self.pos[idx] + HEADER + at, np.full(len(idx), dtype.itemsize), out)
        values: np.ndarray = out.view(dtype)[:, 0]
        return values

    def decode(self, idx: npt.NDArray[np.intp], fmt: DfFormat) -> np.ndarray:
        """Payloads of records ``idx`` (all of type ``fmt``) as a structured array."""
        width = fmt.length - HEADER
        out = np.empty((len(idx), width), np.uint8)
        gather(self.buf, self.pos[idx] + HEADER, np.full(len(idx), width, np.int64), out)
        return out.view(fmt.dtype)[:, 0]


@dataclass
class Unusable:
    """An FMT record that could not be turned into a format."""

    name: str
    offset: int
    reason: str
    columns: tuple[str, ...]


@dataclass
class Formats:
    """Message formats in effect, following FMT records in file order."""

    current: dict[int, DfFormat] = field(default_factory=lambda: {FMT_TYPE: FMT_FORMAT})
    unusable: dict[int, Unusable] = field(default_factory=dict)
    redefined: list[tuple[int, str]] = field(default_factory=list)
    _names: dict[str, set[int]] = field(default_factory=dict)
    _history: dict[int, list[tuple[int, DfFormat | None]]] = field(default_factory=dict)

    def observe(self, rec: Records) -> None:
        """Take the FMT records of a block (in order)."""
        idx = rec.of_type(FMT_TYPE)
        if not len(idx):
            return
        for i in idx.tolist():
            offset = int(rec.offset[i])
            raw = rec.buf[rec.pos[i] + HEADER : rec.pos[i] + FMT_LENGTH].tobytes()
            type_, name, columns, made, error = _format(raw)
            if made is not None:
                self.unusable.pop(type_, None)
            else:
                self.unusable[type_] = Unusable(name, offset, error, columns)
            old = self.current.get(type_)
            if made is not None and old is not None and old.dtype != made.dtype:
                self.redefined.append((offset, name))
            if made is not None:
                self.current[type_] = made
            else:
                self.current.pop(type_, None)
            self._history.setdefault(type_, []).append((offset, made))
            self._names.setdefault(name, set()).add(type_)

    def split(self, type_: int, offsets: I64) -> list[tuple[DfFormat | None, I64]]:
        """(format, indices into ``offsets``) for records of ``type_`` at ``offsets``."""
        hist = self._history.get(type_)
        if type_ == FMT_TYPE:
            return [(FMT_FORMAT, np.arange(len(offsets)))]
        if not hist:
            return [(None, np.arange(len(offsets)))]
        if len(hist) == 1 and (not len(offsets) or offsets[0] >= hist[0][0]):
            return [(hist[0][1], np.arange(len(offsets)))]  # the common case: one FMT
        starts = np.array([o for o, _ in hist], np.int64)
        which = np.searchsorted(starts, offsets, side="right") - 1
        out: list[tuple[DfFormat | None, I64]] = []
        for w in np.unique(which).tolist():
            fmt = hist[w][1] if w >= 0 else None
            out.append((fmt, np.flatnonzero(which == w)))
        return out

    def types_seen(self, name: str) -> list[int]:
        """Every type byte an FMT so far has given the name ``name``."""
        return sorted(self._names.get(name, ()))


@lru_cache(maxsize=4096)
def _format(raw: bytes) -> tuple[int, str, tuple[str, ...], DfFormat | None, str]:
    """(type, name, columns, format or None, why not) of an FMT payload (cached: logs repeat
    their FMTs, and every pass over a log sees them again)."""
    type_, length, name, fmt, columns = parse_fmt(raw)
    try:
        return type_, name, columns, make_format(type_, length, name, fmt, columns), ""
    except FormatError as err:
        return type_, name, columns, None, str(err)


@dataclass
class ScanStats(BlockStats):
    """Garbage and truncation found by one scan, and the records framed."""

    records: int = 0


def scan_blocks(
    path: Path, formats: Formats, stats: ScanStats, *, block_bytes: int | None = None
) -> Iterator[Records]:
    """Yield the records of ``path`` block by block (``BLOCK_BYTES`` unless given), feeding
    ``formats`` and ``stats``."""
    fmt_len = np.zeros(256, np.int32)
    fmt_len[FMT_TYPE] = FMT_LENGTH

    def scan(buf: U8, base: int, final: bool, garbage: int) -> tuple[Records | None, int, int, int]:
        slots = len(buf) // 3 + 2
        pos = np.empty(slots, np.int64)
        typ = np.empty(slots, np.uint8)
        gap_pos = np.empty(slots // 2 + 2, np.int64)
        gap_len = np.empty(slots // 2 + 2, np.int64)
        n, ng, stop, garbage, end = scan_dataflash(
            buf, len(buf), final, base, garbage, fmt_len, pos, typ, gap_pos, gap_len
        )
        rec = Records(buf, pos[:n].copy(), pos[:n] + base, typ[:n].copy())
        stats.records += n
        stats.add_gaps(gap_pos[:ng], gap_len[:ng])
        formats.observe(rec)
        return (rec if n else None), stop, garbage, end

    yield from scan_file(path, block_bytes or BLOCK_BYTES, stats, scan)
