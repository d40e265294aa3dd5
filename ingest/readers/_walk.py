"""Compiled record walkers: find every record in a buffer without Python per record.

The container formats frame their records simply (MCAP: ``opcode u8, length u64, content``;
ROS 1 bag: ``header_len u32, header, data_len u32, data``), but a chunk holds thousands of
records and a Python loop over them costs more than decoding their payloads with numpy.
These numba kernels (``cache=True``) return the position of every complete record as arrays;
the readers then gather message fields vectorised.

Status codes returned with the stop position:

- ``OK``: the buffer ended exactly at a record boundary.
- ``INCOMPLETE``: the record at the stop position runs past the end of the buffer (the
  caller reads more, or reports a truncation); its declared length is returned.
- ``TOO_LONG``: the record at the stop position declares a length above ``limit`` (a corrupt
  length field: no valid record can be longer than the file).
- ``BAD_HEADER``: (ROS 1) a record header is malformed.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from navreplay.ingest.arrays import I64, U8

OK = 0
INCOMPLETE = 1
TOO_LONG = 2
BAD_HEADER = 3


@njit(cache=True, nogil=True)
def _u64(data: U8, pos: int) -> np.uint64:  # pragma: no cover (compiled)
    v = np.uint64(0)
    for k in range(8):
        v |= np.uint64(data[pos + k]) << np.uint64(8 * k)
    return v


@njit(cache=True, nogil=True)
def _u32(data: U8, pos: int) -> int:  # pragma: no cover (compiled)
    return (
        int(data[pos])
        | (int(data[pos + 1]) << 8)
        | (int(data[pos + 2]) << 16)
        | (int(data[pos + 3]) << 24)
    )


@njit(cache=True, nogil=True)
def walk_mcap(
    data: U8, start: int, limit: int, ops: U8, pos: I64, lens: I64
) -> tuple[int, int, int, int]:  # pragma: no cover (compiled)
    """Find MCAP records ``opcode u8 | length u64 | content`` in ``data[start:]``.

    Fills ``ops``, ``pos`` (content start) and ``lens`` (content length) and returns
    ``(count, stop, status, declared_length)``; ``stop`` is where the first unread record
    begins. The output arrays need ``len(data) // 9 + 1`` slots.
    """
    n = len(data)
    p = start
    k = 0
    while True:
        if p == n:
            return k, p, OK, 0
        if p + 9 > n:
            return k, p, INCOMPLETE, -1
        length = _u64(data, p + 1)
        if length > np.uint64(limit):
            return k, p, TOO_LONG, -1
        ln = int(length)
        if p + 9 + ln > n:
            return k, p, INCOMPLETE, ln
        ops[k] = data[p]
        pos[k] = p + 9
        lens[k] = ln
        k += 1
        p = p + 9 + ln


@njit(cache=True, nogil=True)
def _field_is(
    data: U8, name_pos: int, name_len: int, a: int, b: int, c: int, d: int
) -> bool:  # pragma: no cover
    # Compare a header field name with up to 4 ASCII codes (0 = unused).
    want = 0
    for code in (a, b, c, d):
        if code != 0:
            want += 1
    if name_len != want:
        return False
    codes = (a, b, c, d)
    for i in range(want):  # noqa: SIM110 (a generator expression does not compile in nopython)
        if data[name_pos + i] != codes[i]:
            return False
    return True


@njit(cache=True, nogil=True)
def walk_ros1(  # noqa: PLR0911, PLR0912 (one compiled state machine; calls would cost per record)
    data: U8,
    start: int,
    limit: int,
    ops: U8,
    hpos: I64,
    hlen: I64,
    dpos: I64,
    dlen: I64,
    conn: I64,
    time_ns: I64,
) -> tuple[int, int, int, int]:  # pragma: no cover (compiled)
    """Find ROS 1 bag records ``header_len u32 | header | data_len u32 | data``.

    For each record: ``ops`` (the ``op`` header field), header and data positions and lengths,
    and for message records (op 2) the ``conn`` and ``time`` fields (time as ns). Returns
    ``(count, stop, status, declared_length)``. Output arrays need ``len(data) // 8 + 1``.
    """
    n = len(data)
    p = start
    k = 0
    while True:
        if p == n:
            return k, p, OK, 0
        if p + 4 > n:
            return k, p, INCOMPLETE, -1
        hl = _u32(data, p)
        if hl > limit:
            return k, p, TOO_LONG, -1
        if p + 4 + hl + 4 > n:
            return k, p, INCOMPLETE, -1
        dl = _u32(data, p + 4 + hl)
        if dl > limit:
            return k, p, TOO_LONG, -1
        total = 4 + hl + 4 + dl
        if p + total > n:
            return k, p, INCOMPLETE, total
        op = -1
        c = -1
        t = -1
        q = p + 4
        hend = p + 4 + hl
        while q < hend:
            if q + 4 > hend:
                return k, p, BAD_HEADER, -1
            fl = _u32(data, q)
            q += 4
            if q + fl > hend:
                return k, p, BAD_HEADER, -1
            eq = -1
            for j in range(q, q + fl):
                if data[j] == 61:  # '='
                    eq = j
                    break
            if eq < 0:
                return k, p, BAD_HEADER, -1
            name_len = eq - q
            vpos = eq + 1
            vlen = q + fl - vpos
            if _field_is(data, q, name_len, 111, 112, 0, 0) and vlen == 1:  # "op"
                op = int(data[vpos])
            elif _field_is(data, q, name_len, 99, 111, 110, 110) and vlen == 4:  # "conn"
                c = _u32(data, vpos)
            elif _field_is(data, q, name_len, 116, 105, 109, 101) and vlen == 8:  # "time"
                t = _u32(data, vpos) * 1_000_000_000 + _u32(data, vpos + 4)
            q += fl
        if op < 0:
            return k, p, BAD_HEADER, -1
        ops[k] = op
        hpos[k] = p + 4
        hlen[k] = hl
        dpos[k] = p + 4 + hl + 4
        dlen[k] = dl
        conn[k] = c
        time_ns[k] = t
        k += 1
        p += total


def mcap_records(data: U8, start: int, limit: int) -> tuple[U8, I64, I64, int, int, int]:
    """Walk MCAP records of ``data`` from ``start``: (ops, pos, lens, stop, status, declared)."""
    cap = (len(data) - start) // 9 + 1
    ops = np.empty(cap, np.uint8)
    pos = np.empty(cap, np.int64)
    lens = np.empty(cap, np.int64)
    k, stop, status, declared = walk_mcap(data, start, limit, ops, pos, lens)
    return ops[:k], pos[:k], lens[:k], stop, status, declared


def ros1_records(data: U8, start: int, limit: int) -> tuple[dict[str, np.ndarray], int, int, int]:
    """Walk ROS 1 bag records of ``data`` from ``start``: (arrays, stop, status, declared)."""
    cap = (len(data) - start) // 8 + 1
    ops = np.empty(cap, np.uint8)
    ints = {name: np.empty(cap, np.int64) for name in _ROS1_INT_FIELDS}
    k, stop, status, declared = walk_ros1(data, start, limit, ops, *ints.values())
    out: dict[str, np.ndarray] = {"op": ops[:k]}
    out.update({name: arr[:k] for name, arr in ints.items()})
    return out, stop, status, declared


_ROS1_INT_FIELDS = ("hpos", "hlen", "dpos", "dlen", "conn", "time_ns")
