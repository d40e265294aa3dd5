"""One pass over a MAVLink tlog in blocks: framed packets as arrays, and the file's damage.

``scan_blocks(path, dialect, stats)`` reads the file in ``BLOCK_BYTES`` blocks, frames every
record with the compiled ``scan_tlog`` (CRC checked with the dialect's ``crc_extra``) and
yields a ``Packets`` per block: per-packet file offset, stamp, header fields and payload
position, all as arrays. ``ScanStats`` accumulates what a damaged file needs reported: garbage
runs skipped (offset, bytes), packets failing their CRC and packets with msgids the dialect
lacks (per msgid), sequence-number gaps per sender (lost packets), and a trailing partial
record. Memory is one block plus the carried tail of a record cut by the block boundary.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import numpy.typing as npt

from navreplay.ingest.arrays import I64, U8
from navreplay.ingest.readers.mavlink._blocks import BlockStats, scan_file
from navreplay.ingest.readers.mavlink._mavscan import MAVLINK_V2, VALID, scan_tlog
from navreplay.ingest.readers.mavlink.mavdialect import Dialect

BLOCK_BYTES = 8 << 20
MIN_STAMP_US = 946_684_800 * 10**6  # 2000-01-01
MAX_STAMP_US = 4_102_444_800 * 10**6  # 2100-01-01

_AR8 = np.arange(8, dtype=np.int64)


@dataclass
class Packets:
    """The framed packets of one block (all arrays have one entry per packet).

    Attributes:
        buf: the block's bytes; ``payload``/``pos`` index into it.
        offset: file offset of each record (its 8-byte stamp).
        flag: ``VALID``, ``BAD_CRC`` or ``UNKNOWN`` (``ingest.readers.mavlink._mavscan``).
        stamp_us: the tlog's UNIX stamp (UTC, microseconds).
        msgid, sysid, compid, seq: header fields.
        payload: offset in ``buf`` of the payload; ``payload_len`` its (possibly trimmed)
            length.
    """

    buf: U8
    offset: I64
    flag: npt.NDArray[np.int8]
    stamp_us: I64
    msgid: I64
    sysid: I64
    compid: I64
    seq: I64
    payload: I64
    payload_len: I64

    def __len__(self) -> int:
        return len(self.offset)

    @property
    def source(self) -> I64:
        """``sysid * 256 + compid`` per packet."""
        return self.sysid * 256 + self.compid


@dataclass
class ScanStats(BlockStats):
    """Damage and counts accumulated over one scan of the file."""

    packets: int = 0
    bad_crc: Counter[int] = field(default_factory=Counter)
    bad_crc_first: int | None = None
    unknown: Counter[int] = field(default_factory=Counter)
    valid: Counter[int] = field(default_factory=Counter)
    lost_by_source: Counter[int] = field(default_factory=Counter)
    _last_seq: dict[int, int] = field(default_factory=dict)

    def observe(self, p: Packets) -> None:
        self.packets += len(p)
        ok = p.flag == VALID
        self.valid.update(_counts(p.msgid[ok]))
        bad = p.flag == 1
        if bad.any():
            self.bad_crc.update(_counts(p.msgid[bad]))
            if self.bad_crc_first is None:
                self.bad_crc_first = int(p.offset[bad][0])
        unknown = p.flag == 2
        if unknown.any():
            self.unknown.update(_counts(p.msgid[unknown]))
        self._seq_gaps(p.source[ok], p.seq[ok])

    def _seq_gaps(self, source: I64, seq: I64) -> None:
        for src in np.unique(source).tolist():
            s = seq[source == src]
            last = self._last_seq.get(src)
            chain = np.concatenate([[last], s]) if last is not None else s
            lost = int(((np.diff(chain) - 1) % 256).sum())
            if lost:
                self.lost_by_source[src] += lost
            self._last_seq[src] = int(s[-1])


def _counts(ids: I64) -> dict[int, int]:
    values, counts = np.unique(ids, return_counts=True)
    return dict(zip(values.tolist(), counts.tolist(), strict=True))


def packet_fields(buf: U8, pos: I64, flag: npt.NDArray[np.int8], base: int) -> Packets:
    """Header fields of the records starting at ``pos`` (offsets in ``buf``)."""
    stamp = buf[pos[:, None] + _AR8].copy().view(">u8")[:, 0].astype(np.int64)
    v2 = buf[pos + 8] == MAVLINK_V2
    at = pos + 8

    def byte(k1: int, k2: int) -> I64:
        return np.where(v2, buf[at + k2], buf[at + k1]).astype(np.int64)

    msgid = np.where(
        v2,
        buf[np.minimum(at + 7, len(buf) - 1)].astype(np.int64)
        | (buf[np.minimum(at + 8, len(buf) - 1)].astype(np.int64) << 8)
        | (buf[np.minimum(at + 9, len(buf) - 1)].astype(np.int64) << 16),
        buf[at + 5].astype(np.int64),
    )
    return Packets(
        buf=buf,
        offset=pos + base,
        flag=flag,
        stamp_us=stamp,
        msgid=msgid,
        sysid=byte(3, 5),
        compid=byte(4, 6),
        seq=byte(2, 4),
        payload=at + np.where(v2, 10, 6),
        payload_len=buf[at + 1].astype(np.int64),
    )


def scan_blocks(
    path: Path, dialect: Dialect, stats: ScanStats, *, block_bytes: int | None = None
) -> Iterator[Packets]:
    """Yield the packets of ``path`` block by block (``BLOCK_BYTES`` unless given); ``stats``
    collects the damage."""

    def scan(buf: U8, base: int, final: bool, garbage: int) -> tuple[Packets | None, int, int, int]:
        slots = len(buf) // 16 + 2
        pos = np.empty(slots, np.int64)
        flag = np.empty(slots, np.int8)
        gap_pos = np.empty(slots, np.int64)
        gap_len = np.empty(slots, np.int64)
        n, ng, stop, garbage, end = scan_tlog(
            buf,
            len(buf),
            final,
            base,
            garbage,
            dialect.crc_extra,
            MIN_STAMP_US,
            MAX_STAMP_US,
            pos,
            flag,
            gap_pos,
            gap_len,
        )
        packets = packet_fields(buf, pos[:n], flag[:n], base)
        stats.add_gaps(gap_pos[:ng], gap_len[:ng])
        stats.observe(packets)
        return (packets if n else None), stop, garbage, end

    yield from scan_file(path, block_bytes or BLOCK_BYTES, stats, scan)
