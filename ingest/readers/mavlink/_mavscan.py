"""Compiled framing scans for MAVLink tlogs and ArduPilot DataFlash logs, and payload gathers.

Both formats are a plain sequence of small records with no index, so finding the records is
a byte-level loop; these numba kernels (``cache=True``) do it once per block and return the
position of every record as arrays. The readers then group records by message and decode
payloads column-wise (``gather`` + a structured dtype), never per packet in Python.

tlog (``scan_tlog``): ``[u64 big-endian UNIX us][MAVLink v1 (0xFE) or v2 (0xFD) packet]``.
A record is accepted when its stamp is plausible (``min_us..max_us``), its start byte and
length frame it, and its X.25 CRC (seeded with the message's ``crc_extra``) matches. A framed
record whose CRC fails, or whose msgid the dialect lacks, is accepted as ``BAD_CRC`` /
``UNKNOWN`` only when the next record frames too (plausible stamp, start byte and length:
the framing is then right and only this packet is damaged or foreign); otherwise its bytes
are garbage. Garbage is skipped one byte
at a time until a record with a valid CRC starts (resynchronisation), and each skipped run is
returned with its offset and length.

DataFlash (``scan_dataflash``): ``0xA3 0x95 type payload``, lengths from the FMT records seen
so far (``fmt_len``, updated by the kernel as FMT records pass, FMT itself preset to 89
bytes). DataFlash has no CRC: after garbage, a candidate record is accepted only when the
record after it starts with a known header too; and a record followed by garbage is itself
taken as garbage when a chain of two records starts inside it (garbage that happens to
begin like a header).

Both kernels work on blocks: with ``final`` false they stop before a record that runs past
the block end and return its position (the caller carries the tail into the next block);
with ``final`` true such a record is a trailing partial record (``end_status`` PARTIAL). A
garbage run in progress at a block end is carried as ``garbage_start`` (absolute offset).
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt
from numba import njit

from navreplay.ingest.arrays import I16, I32, I64, U8
from navreplay.ingest.damage import Completeness, Defect

# Record flags (tlog).
VALID = 0
BAD_CRC = 1
UNKNOWN = 2
# Internal framing statuses.
_NEED_MORE = 3
_INVALID = 4
# End status of a scan.
END_OK = 0
END_PARTIAL = 1

MAVLINK_V1 = 0xFE
MAVLINK_V2 = 0xFD
DF_HEAD1 = 0xA3
DF_HEAD2 = 0x95
DF_FMT_TYPE = 128
DF_FMT_LEN = 89
_DF_LOOKAHEAD = 2 * 256 + 3  # a record is at most 255 bytes: room for a chain inside it


@njit(cache=True, nogil=True)
def x25_crc(buf: U8, start: int, stop: int, extra: int) -> int:  # pragma: no cover
    """CRC-16/MCRF4XX (MAVLink's X.25) of ``buf[start:stop]`` followed by the byte ``extra``."""
    crc = 0xFFFF
    for i in range(start, stop + 1):
        b = extra if i == stop else int(buf[i])
        tmp = b ^ (crc & 0xFF)
        tmp = (tmp ^ (tmp << 4)) & 0xFF
        crc = ((crc >> 8) ^ (tmp << 8) ^ (tmp << 3) ^ (tmp >> 4)) & 0xFFFF
    return crc


@njit(cache=True, nogil=True)
def _frame_tlog(  # noqa: PLR0911, PLR0912 (one compiled framing check, early exits)
    buf: U8, p: int, end: int, crc_extra: I16, min_us: int, max_us: int
) -> tuple[int, int]:  # pragma: no cover
    """(status, record length incl. the 8-byte stamp) of the record at ``p``."""
    if p + 9 > end:
        return _NEED_MORE, 0
    stamp = 0
    for k in range(8):
        stamp = (stamp << 8) | int(buf[p + k])
        if k == 0 and buf[p] != 0:  # beyond 2^56 us: never a plausible stamp
            return _INVALID, 0
    if stamp < min_us or stamp > max_us:
        return _INVALID, 0
    stx = buf[p + 8]
    if stx == MAVLINK_V1:
        if p + 14 > end:
            return _NEED_MORE, 0
        plen = int(buf[p + 9])
        hlen = 6
        size = 8 + 8 + plen
        msgid = int(buf[p + 13])
    elif stx == MAVLINK_V2:
        if p + 18 > end:
            return _NEED_MORE, 0
        plen = int(buf[p + 9])
        incompat = int(buf[p + 10])
        if incompat & 0xFE:
            return _INVALID, 0
        hlen = 10
        size = 8 + 12 + plen + (13 if incompat & 1 else 0)
        msgid = int(buf[p + 15]) | (int(buf[p + 16]) << 8) | (int(buf[p + 17]) << 16)
    else:
        return _INVALID, 0
    if p + size > end:
        return _NEED_MORE, size
    if msgid >= len(crc_extra) or crc_extra[msgid] < 0:
        return UNKNOWN, size
    at = p + 8 + hlen + plen
    stored = int(buf[at]) | (int(buf[at + 1]) << 8)
    if x25_crc(buf, p + 9, at, int(crc_extra[msgid])) == stored:
        return VALID, size
    return BAD_CRC, size


@njit(cache=True, nogil=True)
def _end_gap(gap_pos: I64, gap_len: I64, ng: int, start: int, stop: int) -> int:  # pragma: no cover
    """Store the garbage run ``start..stop`` (absolute offsets) as gap ``ng``; the new count."""
    gap_pos[ng] = start
    gap_len[ng] = stop - start
    return ng + 1


@njit(cache=True, nogil=True)
def scan_tlog(
    buf: U8,
    end: int,
    final: bool,
    base: int,
    garbage_start: int,
    crc_extra: I16,
    min_us: int,
    max_us: int,
    rec_pos: I64,
    rec_flag: npt.NDArray[np.int8],
    gap_pos: I64,
    gap_len: I64,
) -> tuple[int, int, int, int, int]:  # pragma: no cover
    """Frame the tlog records of ``buf[:end]`` (``buf[0]`` is file offset ``base``).

    Fills ``rec_pos`` (offset in ``buf`` of each record's stamp) and ``rec_flag`` (VALID,
    BAD_CRC, UNKNOWN), and ``gap_pos``/``gap_len`` (absolute offset and length of each
    garbage run that ended in this block). Output arrays need ``end // 16 + 2`` slots.

    Returns:
        (records, gaps, stop, garbage_start, end_status): ``stop`` is the offset in ``buf``
        where scanning stopped (the caller carries ``buf[stop:end]``); ``garbage_start`` the
        absolute start of a garbage run still open (-1 if none).
    """
    n = 0
    ng = 0
    p = 0
    while p < end:
        status, size = _frame_tlog(buf, p, end, crc_extra, min_us, max_us)
        if garbage_start >= 0:
            if status == VALID:
                ng = _end_gap(gap_pos, gap_len, ng, garbage_start, base + p)
                garbage_start = -1
            elif status == _NEED_MORE and not final:
                return n, ng, p, garbage_start, END_OK
            else:
                p += 1
                continue
        if status == VALID:
            rec_pos[n] = p
            rec_flag[n] = VALID
            n += 1
            p += size
            continue
        if status == _NEED_MORE:
            if not final:
                return n, ng, p, garbage_start, END_OK
            return n, ng, p, garbage_start, END_PARTIAL
        if status in (BAD_CRC, UNKNOWN):
            q = p + size
            nxt, _ = _frame_tlog(buf, q, end, crc_extra, min_us, max_us)
            if nxt == _NEED_MORE and not final and q < end:
                return n, ng, p, garbage_start, END_OK
            if q == end or nxt in (VALID, BAD_CRC, UNKNOWN) or (nxt == _NEED_MORE and final):
                rec_pos[n] = p
                rec_flag[n] = status
                n += 1
                p = q
                continue
        garbage_start = base + p
        p += 1
    if garbage_start >= 0 and final:
        ng = _end_gap(gap_pos, gap_len, ng, garbage_start, base + end)
        garbage_start = -1
    return n, ng, end, garbage_start, END_OK


@njit(cache=True, nogil=True)
def _df_known(buf: U8, p: int, fmt_len: I32) -> int:  # pragma: no cover
    """Length of the DataFlash record whose header is at ``p``, 0 if it is not one."""
    if buf[p] != DF_HEAD1 or buf[p + 1] != DF_HEAD2:
        return 0
    return int(fmt_len[buf[p + 2]])


@njit(cache=True, nogil=True)
def _df_chain(buf: U8, s: int, end: int, fmt_len: I32) -> bool:  # pragma: no cover
    """A record starts at ``s`` and another right after it (or the data ends there)."""
    if s + 3 > end:
        return False
    length = _df_known(buf, s, fmt_len)
    if length == 0:
        return False
    q = s + length
    return q == end or (q + 3 <= end and _df_known(buf, q, fmt_len) > 0)


@njit(cache=True, nogil=True)
def scan_dataflash(  # noqa: PLR0912 (one compiled state machine; calls cost per record)
    buf: U8,
    end: int,
    final: bool,
    base: int,
    garbage_start: int,
    fmt_len: I32,
    rec_pos: I64,
    rec_type: U8,
    gap_pos: I64,
    gap_len: I64,
) -> tuple[int, int, int, int, int]:  # pragma: no cover
    """Frame the DataFlash records of ``buf[:end]`` (``buf[0]`` is file offset ``base``).

    ``fmt_len`` (256 entries, 0 = type not defined yet) is updated in place as FMT records
    pass. Output arrays need ``end // 3 + 2`` slots. Returns as ``scan_tlog``.
    """
    n = 0
    ng = 0
    p = 0
    while p < end:
        if p + 3 > end:
            if not final:
                return n, ng, p, garbage_start, END_OK
            if garbage_start < 0:
                garbage_start = base + p
            break
        length = _df_known(buf, p, fmt_len)
        if garbage_start >= 0:
            if length == 0:
                p += 1
                continue
            q = p + length
            if q + 3 > end and not final:
                return n, ng, p, garbage_start, END_OK
            if q < end and (q + 3 > end or _df_known(buf, q, fmt_len) == 0):
                p += 1
                continue
            ng = _end_gap(gap_pos, gap_len, ng, garbage_start, base + p)
            garbage_start = -1
        if length == 0:
            garbage_start = base + p
            p += 1
            continue
        if p + length > end:
            if not final:
                return n, ng, p, garbage_start, END_OK
            return n, ng, p, garbage_start, END_PARTIAL
        q = p + length
        if q + 3 <= end and _df_known(buf, q, fmt_len) == 0:
            # Garbage follows, or this header is itself garbage that happens to look like
            # one: it is garbage when a chain of records starts inside it.
            if not final and p + _DF_LOOKAHEAD > end:
                return n, ng, p, garbage_start, END_OK
            s = p + 1
            while s < q and not _df_chain(buf, s, end, fmt_len):
                s += 1
            if s < q:
                garbage_start = base + p
                p = s
                continue
        rec_pos[n] = p
        rec_type[n] = buf[p + 2]
        n += 1
        if buf[p + 2] == DF_FMT_TYPE and length >= 5 and buf[p + 4] >= 3:
            fmt_len[buf[p + 3]] = buf[p + 4]
        p += length
    if garbage_start >= 0 and final:
        ng = _end_gap(gap_pos, gap_len, ng, garbage_start, base + end)
        garbage_start = -1
    return n, ng, end, garbage_start, END_OK


@njit(cache=True, nogil=True)
def gather(buf: U8, pos: I64, lens: I64, out: U8) -> None:  # pragma: no cover
    """``out[i, :lens[i]] = buf[pos[i]:pos[i] + lens[i]]``, zero-padded to ``out.shape[1]``.

    MAVLink 2 trims trailing zero bytes of a payload and MAVLink 1 packets lack the extension
    fields: padding with zeros restores both to the full wire layout.
    """
    width = out.shape[1]
    for i in range(len(pos)):
        m = min(int(lens[i]), width)
        start = pos[i]
        for k in range(m):
            out[i, k] = buf[start + k]
        for k in range(m, width):
            out[i, k] = 0


def partial_record_defect(offset: int, n_bytes: int) -> Defect:
    """The defect of a log that ends inside its last record (``n_bytes`` from ``offset``)."""
    return Defect(
        Completeness.PARTIAL_RECORD_DROPPED,
        f"1 trailing partial record dropped at offset {offset} "
        f"({n_bytes} bytes): the file ends inside it",
        offset=offset,
        messages_lost=1,
        bytes_skipped=n_bytes,
    )
