"""MCAP with ROS 1 (``ros1``/``ros1msg``) and ROS 2 (``cdr``/``ros2msg``/``ros2idl``) messages.

Reading is one linear pass over the data section, so it never depends on the summary or
the index and salvages what a damaged file still holds:

- every record length is checked against the file size before anything is allocated (a
  corrupt 2^40 length is reported, not allocated: catalogue case 5);
- every chunk is decompressed and its CRC verified; a chunk that fails is skipped and
  reported with its offset, its time range (chunk header) and its message count (the
  message-index records that follow it) (case 3/4);
- a file that ends early keeps every complete record and the readable prefix of the chunk
  it ends in (case 1); a missing summary or footer loses nothing (case 2);
- the data-section CRC in DataEnd is verified when the writer set one.

Record content is parsed with the ``mcap`` package's record classes; message records are
located by the compiled walker (``ingest.readers._walk``) and decoded column-wise.
``inventory()`` uses the summary section (statistics, chunk indexes) when the file has a
valid one, and a full scan otherwise.
"""

from __future__ import annotations

import io
import struct
import zlib
from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np
from mcap.data_stream import ReadDataStream
from mcap.exceptions import McapError
from mcap.opcode import Opcode
from mcap.records import Channel, ChunkIndex, Schema, Statistics

from navreplay.ingest.arrays import I64, U8
from navreplay.ingest.damage import Completeness, DamageLog, Defect
from navreplay.ingest.detect import MCAP_MAGIC, Detected, Format
from navreplay.ingest.errors import CorruptLogError
from navreplay.ingest.readers._compression import MAX_CHUNK_BYTES, DecompressError, decompress
from navreplay.ingest.readers._walk import INCOMPLETE, OK, TOO_LONG, mcap_records
from navreplay.ingest.readers.base import (
    Batch,
    Inventory,
    LogReader,
    ReadContext,
    Selection,
    StreamInfo,
)
from navreplay.ingest.readers.ros.roscommon import (
    RosChannel,
    decode_batch,
    make_channel,
    stream_info,
)

BLOCK_BYTES = 4 << 20
_FOOTER_BYTES = 1 + 8 + 20 + len(MCAP_MAGIC)
_AR2 = np.arange(2, dtype=np.int64)
_AR8 = np.arange(8, dtype=np.int64)


@dataclass
class _Segment:
    """Message records found in one buffer (a chunk's records or a run of top-level ones)."""

    buf: U8
    pos: I64  # content start of each message record
    lens: I64  # content length
    offsets: I64  # file offset reported per row (the record, or its chunk)

    def channel_ids(self) -> I64:
        raw = self.buf[self.pos[:, None] + _AR2]
        return np.asarray(raw.view("<u2")[:, 0], dtype=np.int64)

    def log_times(self) -> I64:
        raw = self.buf[(self.pos + 6)[:, None] + _AR8]
        return np.asarray(raw.view("<u8")[:, 0], dtype=np.int64)


@dataclass
class _Pending:
    """A corrupt chunk whose lost-message count is read from the message indexes after it."""

    offset: int
    reason: str
    time_range: tuple[int, int] | None
    lost: int = 0
    indexed: bool = False


class McapReader(LogReader):
    """Reader of one MCAP file (also used for rosbag2 MCAP storage files)."""

    format = Format.MCAP

    def __init__(self, detected: Detected, ctx: ReadContext) -> None:
        super().__init__(detected, ctx)
        self.size = self.file.stat().st_size
        self.channels: dict[int, RosChannel] = {}
        self._schemas: dict[int, Schema] = {}
        self._raw_channels: dict[int, Channel] = {}
        self._crc_missing_noted = False

    # ----------------------------------------------------------------------------- inventory
    def inventory(self) -> Inventory:
        summary = self._read_summary()
        if summary is not None:
            return summary
        scratch = DamageLog(self.file, strict=False)
        counts: dict[int, int] = {}
        first: dict[int, int] = {}
        last: dict[int, int] = {}
        for seg in self._walk(scratch):
            ids = seg.channel_ids()
            times = seg.log_times()
            for cid in np.unique(ids).tolist():
                t = times[ids == cid]
                counts[cid] = counts.get(cid, 0) + len(t)
                first[cid] = min(first.get(cid, int(t.min())), int(t.min()))
                last[cid] = max(last.get(cid, int(t.max())), int(t.max()))
        notes = ["no usable summary section: streams counted by a full scan"]
        notes += [d.reason for d in scratch.defects]
        return self._inventory_from(counts, first, last, notes)

    def _inventory_from(
        self,
        counts: dict[int, int],
        first: dict[int, int],
        last: dict[int, int],
        notes: list[str],
    ) -> Inventory:
        by_topic: dict[str, list[int]] = {}
        for cid, ch in sorted(self.channels.items()):
            by_topic.setdefault(ch.key, []).append(cid)
        streams: list[StreamInfo] = []
        for cids in by_topic.values():
            present = [c for c in cids if c in counts] or cids
            ch = self.channels[present[0]]
            n = sum(counts.get(c, 0) for c in cids)
            starts = [first[c] for c in cids if c in first]
            ends = [last[c] for c in cids if c in last]
            streams.append(
                stream_info(ch, n, min(starts) if starts else None, max(ends) if ends else None)
            )
        return Inventory(self.path, self.format, tuple(streams), tuple(notes))

    def _summary_bytes(self) -> bytes | None:
        """The summary section (checked against the footer's CRC), or None without one."""
        if self.size < len(MCAP_MAGIC) + _FOOTER_BYTES:
            return None
        with self.file.open("rb") as fh:
            fh.seek(self.size - _FOOTER_BYTES)
            tail = fh.read(_FOOTER_BYTES)
            if tail[-8:] != MCAP_MAGIC or tail[0] != Opcode.FOOTER:
                return None
            summary_start, _offsets_start, summary_crc = struct.unpack_from("<QQI", tail, 9)
            footer_at = self.size - _FOOTER_BYTES
            if not 8 <= summary_start < footer_at:
                return None
            fh.seek(summary_start)
            body = fh.read(footer_at - summary_start)
        if summary_crc and zlib.crc32(tail[:-12], zlib.crc32(body)) != summary_crc:
            return None
        return body

    def _read_summary(self) -> Inventory | None:
        body = self._summary_bytes()
        if body is None:
            return None
        arr = np.frombuffer(body, np.uint8)
        ops, pos, lens, _stop, status, _ = mcap_records(arr, 0, len(body))
        if status != OK:
            return None
        stats: list[Statistics] = []
        chunk_indexes: list[ChunkIndex] = []
        readers = {
            Opcode.SCHEMA: lambda st: self._add_schema(Schema.read(st)),
            Opcode.CHANNEL: lambda st: self._add_channel(Channel.read(st)),
            Opcode.STATISTICS: lambda st: stats.append(Statistics.read(st)),
            Opcode.CHUNK_INDEX: lambda st: chunk_indexes.append(ChunkIndex.read(st)),
        }
        try:
            for op, p, n in zip(ops.tolist(), pos.tolist(), lens.tolist(), strict=True):
                if op in readers:
                    readers[op](ReadDataStream(io.BytesIO(body[p : p + n])))
        except (McapError, UnicodeDecodeError, struct.error):
            return None
        if not stats or not self.channels:
            return None
        first: dict[int, int] = {}
        last: dict[int, int] = {}
        for ci in chunk_indexes:
            for cid in ci.message_index_offsets:
                first[cid] = min(first.get(cid, ci.message_start_time), ci.message_start_time)
                last[cid] = max(last.get(cid, ci.message_end_time), ci.message_end_time)
        if not chunk_indexes:
            for cid in stats[0].channel_message_counts:
                first[cid], last[cid] = stats[0].message_start_time, stats[0].message_end_time
        notes = ["times from the chunk index (chunk granularity)"] if chunk_indexes else []
        return self._inventory_from(dict(stats[0].channel_message_counts), first, last, notes)

    # ---------------------------------------------------------------------------------- read
    def read(self, selections: Sequence[Selection]) -> Iterator[Batch]:
        keys = {s.key for s in selections}
        self.damage.note(
            "MCAP chunk CRCs verified where the writer stored them; record lengths bounded by "
            "the file size"
        )
        for seg in self._walk(self.damage):
            ids = seg.channel_ids()
            times = seg.log_times()
            for cid in np.unique(ids).tolist():
                ch = self.channels.get(cid)
                if ch is None:
                    self.damage.count("messages_on_unknown_channel", int((ids == cid).sum()))
                    continue
                if ch.key not in keys or ch.conversion is None:
                    continue
                sel = np.flatnonzero(ids == cid)
                pos = seg.pos[sel]
                yield decode_batch(
                    self.file,
                    ch,
                    seg.buf,
                    pos + 22,
                    pos + seg.lens[sel],
                    times[sel],
                    seg.offsets[sel],
                    strict=self.damage.strict,
                )

    # --------------------------------------------------------------------------------- walk
    def _walk(self, damage: DamageLog) -> Iterator[_Segment]:
        """One pass over the data section, yielding message segments in file order."""
        with self.file.open("rb") as fh:
            if fh.read(len(MCAP_MAGIC)) != MCAP_MAGIC:
                raise CorruptLogError("not an MCAP file (bad magic)", path=self.file, offset=0)
            state = _WalkState(crc=zlib.crc32(MCAP_MAGIC))
            base = len(MCAP_MAGIC)
            carry = b""
            while True:
                want = max(BLOCK_BYTES, state.need)
                fresh = fh.read(want)
                data = carry + fresh if carry else fresh
                at_eof = base + len(data) >= self.size
                arr = np.frombuffer(data, np.uint8)
                ops, pos, lens, stop, status, declared = mcap_records(arr, 0, self.size)
                yield from self._records(arr, base, ops, pos, lens, state, damage)
                if state.done:
                    break
                state.crc = zlib.crc32(memoryview(data)[:stop], state.crc)
                if status == TOO_LONG:
                    self._corrupt_length(damage, base + stop, arr, stop)
                    break
                if status == OK and at_eof:
                    damage.record(
                        Defect(
                            Completeness.NO_SUMMARY,
                            "the file ends after the last complete record without a "
                            "DataEnd record, summary or footer (recorder stopped before "
                            "finishing): every message recovered",
                            offset=base + stop,
                        )
                    )
                    break
                if status == INCOMPLETE and at_eof:
                    yield from self._truncated(damage, arr, stop, base, state)
                    break
                carry = data[stop:]
                base += stop
                state.need = (9 + declared - len(carry)) if declared >= 0 else 0
        self._flush_pending(state, damage)
        if state.done:
            self._trailing_bytes(state.end_at, damage)
        if state.done and not self._has_footer():
            damage.record(
                Defect(
                    Completeness.NO_SUMMARY,
                    "the summary section or footer after DataEnd is missing or damaged: every "
                    "message recovered from the data section",
                    offset=None,
                )
            )

    def _trailing_bytes(self, start: int, damage: DamageLog) -> None:
        """Bytes after the closing magic that follows DataEnd (a copy of the file appended, a
        second recording) are not read: say so."""
        with self.file.open("rb") as fh:
            fh.seek(start)
            at, tail = start, b""
            while chunk := fh.read(1 << 20):
                hit = (tail + chunk).find(MCAP_MAGIC)
                if hit >= 0:
                    end = at - len(tail) + hit + len(MCAP_MAGIC)
                    break
                tail = chunk[-(len(MCAP_MAGIC) - 1) :]
                at += len(chunk)
            else:
                return
        if end < self.size:
            damage.record(
                Defect(
                    Completeness.CORRUPT_TAIL,
                    f"{self.size - end} bytes after the end of the MCAP file (its closing magic "
                    f"at offset {end - len(MCAP_MAGIC)}) ignored: a copy or another recording "
                    "appended?",
                    offset=end,
                    bytes_skipped=self.size - end,
                )
            )

    def _has_footer(self) -> bool:
        if self.size < len(MCAP_MAGIC) + _FOOTER_BYTES:
            return False
        with self.file.open("rb") as fh:
            fh.seek(self.size - _FOOTER_BYTES)
            tail = fh.read(_FOOTER_BYTES)
        return tail[-8:] == MCAP_MAGIC and tail[0] == Opcode.FOOTER

    def _records(
        self,
        arr: U8,
        base: int,
        ops: U8,
        pos: I64,
        lens: I64,
        state: _WalkState,
        damage: DamageLog,
    ) -> Iterator[_Segment]:
        msg_mask = ops == Opcode.MESSAGE
        if msg_mask.all() and len(ops):
            yield _Segment(arr, pos, lens, base + pos - 9)
            return
        run: list[int] = []
        for i, op in enumerate(ops.tolist()):
            if op == Opcode.MESSAGE:
                run.append(i)
                continue
            if run:
                idx = np.asarray(run)
                yield _Segment(arr, pos[idx], lens[idx], base + pos[idx] - 9)
                run = []
            p, n = int(pos[i]), int(lens[i])
            offset = base + p - 9
            if op == Opcode.CHUNK:
                self._flush_pending(state, damage)
                seg = self._chunk(arr[p : p + n], offset, damage, state)
                if seg is not None:
                    yield seg
            elif op in (Opcode.SCHEMA, Opcode.CHANNEL):
                self._definition(op, arr[p : p + n], offset, damage)
            elif op == Opcode.MESSAGE_INDEX and state.pending is not None and n >= 6:
                (records_len,) = struct.unpack_from("<I", arr.data, p + 2)
                state.pending.lost += records_len // 16
                state.pending.indexed = True
            elif op == Opcode.DATA_END:
                state.crc = zlib.crc32(arr.data[: p - 9], state.crc)
                self._check_data_crc(arr, p, n, offset, state, damage)
                state.done, state.end_at = True, offset
                return
            elif op == Opcode.FOOTER:
                state.done, state.end_at = True, offset
                return
        if run:
            idx = np.asarray(run)
            yield _Segment(arr, pos[idx], lens[idx], base + pos[idx] - 9)

    def _definition(self, op: int, content: U8, offset: int, damage: DamageLog) -> None:
        try:
            stream = ReadDataStream(io.BytesIO(content.tobytes()))
            if op == Opcode.SCHEMA:
                self._add_schema(Schema.read(stream))
            else:
                self._add_channel(Channel.read(stream))
        except (McapError, UnicodeDecodeError, struct.error) as err:
            raise CorruptLogError(
                f"unreadable {'schema' if op == Opcode.SCHEMA else 'channel'} record: {err}",
                path=self.file,
                offset=offset,
            ) from err

    def _add_schema(self, schema: Schema) -> None:
        self._schemas[schema.id] = schema
        for cid, ch in list(self._raw_channels.items()):
            known = self.channels.get(cid)
            if ch.schema_id == schema.id and known is not None and known.decoder is None:
                del self.channels[cid]
                self._add_channel(ch)

    def _add_channel(self, ch: Channel) -> None:
        self._raw_channels[ch.id] = ch
        if ch.id in self.channels:
            return
        schema = self._schemas.get(ch.schema_id)
        if schema is None:
            self.channels[ch.id] = make_channel(ch.topic, "?", ch.message_encoding, None)
            return
        fmt: Literal["msg", "idl"] = "idl" if schema.encoding == "ros2idl" else "msg"
        text = schema.data.decode("utf-8", "replace")
        self.channels[ch.id] = make_channel(
            ch.topic, schema.name, ch.message_encoding, text if schema.data else None, fmt
        )

    # -------------------------------------------------------------------------------- chunks
    def _chunk(
        self, content: U8, offset: int, damage: DamageLog, state: _WalkState
    ) -> _Segment | None:
        header = _parse_chunk_header(content)
        if header is None:
            state.pending = _Pending(offset, "chunk header is malformed", None)
            return None
        start_t, end_t, usize, crc, compression, rec_at, rec_len = header
        records = content[rec_at : rec_at + rec_len]
        try:
            raw = decompress(compression, records.tobytes(), usize)
        except DecompressError as err:
            state.pending = _Pending(offset, f"chunk does not decompress ({err})", (start_t, end_t))
            return None
        if crc == 0:
            if not self._crc_missing_noted:
                damage.note("chunks carry no CRC: corruption inside them cannot be detected")
                self._crc_missing_noted = True
        elif (got := zlib.crc32(raw)) != crc:
            state.pending = _Pending(
                offset,
                f"chunk failed its CRC check (stored {crc:#010x}, computed {got:#010x})",
                (start_t, end_t),
            )
            return None
        arr = np.frombuffer(raw, np.uint8)
        ops, pos, lens, stop, status, _ = mcap_records(arr, 0, len(raw))
        if status != OK:
            state.pending = _Pending(
                offset, f"records inside the chunk are malformed at byte {stop}", (start_t, end_t)
            )
            return None
        return self._chunk_segment(arr, ops, pos, lens, offset, damage)

    def _chunk_segment(
        self,
        arr: U8,
        ops: U8,
        pos: I64,
        lens: I64,
        offset: int,
        damage: DamageLog,
    ) -> _Segment:
        for i in np.flatnonzero(ops != Opcode.MESSAGE).tolist():
            op = int(ops[i])
            if op in (Opcode.SCHEMA, Opcode.CHANNEL):
                p, n = int(pos[i]), int(lens[i])
                self._definition(op, arr[p : p + n], offset, damage)
        msg = np.flatnonzero(ops == Opcode.MESSAGE)
        return _Segment(arr, pos[msg], lens[msg], np.full(len(msg), offset, np.int64))

    def _flush_pending(self, state: _WalkState, damage: DamageLog) -> None:
        p = state.pending
        if p is None:
            return
        state.pending = None
        lost = p.lost if p.indexed else None
        what = f"{lost} messages lost" if lost is not None else "message count unknown (no index)"
        damage.record(
            Defect(
                Completeness.CORRUPT_CHUNKS_SKIPPED,
                f"{p.reason}: chunk skipped, {what}",
                offset=p.offset,
                messages_lost=lost,
                time_range_ns=p.time_range,
            )
        )

    # ------------------------------------------------------------------------------- damage
    def _truncated(
        self, damage: DamageLog, arr: U8, stop: int, base: int, state: _WalkState
    ) -> Iterator[_Segment]:
        self._flush_pending(state, damage)
        offset = base + stop
        recovered = 0
        if len(arr) - stop >= 9 and arr[stop] == Opcode.CHUNK:
            seg = self._partial_chunk(arr[stop + 9 :], offset, damage)
            if seg is not None and len(seg.pos):
                recovered = len(seg.pos)
                yield seg
        where = f"inside a record at offset {offset}"
        extra = (
            f"; {recovered} messages recovered from the readable prefix of that chunk "
            "(its CRC cannot be verified)"
            if recovered
            else ""
        )
        damage.record(
            Defect(
                Completeness.TRUNCATED,
                f"file truncated {where} ({self.size} bytes): every complete record before "
                f"it was read{extra}",
                offset=offset,
                messages_recovered=recovered or None,
                bytes_skipped=self.size - offset,
            )
        )

    def _partial_chunk(self, content: U8, offset: int, damage: DamageLog) -> _Segment | None:
        header = _parse_chunk_header(content, partial=True)
        if header is None:
            return None
        _s, _e, usize, _crc, compression, rec_at, rec_len = header
        records = content[rec_at : rec_at + rec_len]
        try:
            raw = decompress(compression, records.tobytes(), usize, partial=True)
        except DecompressError:
            return None
        arr = np.frombuffer(raw, np.uint8)
        ops, pos, lens, _stop, _status, _ = mcap_records(arr, 0, len(raw))
        return self._chunk_segment(arr, ops, pos, lens, offset, damage)

    def _corrupt_length(self, damage: DamageLog, offset: int, arr: U8, stop: int) -> None:
        (length,) = struct.unpack_from("<Q", arr.data, stop + 1) if len(arr) >= stop + 9 else (-1,)
        damage.record(
            Defect(
                Completeness.CORRUPT_TAIL,
                f"record at offset {offset} declares a length of {length} bytes, more than the "
                f"whole file ({self.size} bytes): the length field is corrupt and nothing after "
                "it can be framed; every record before it was read",
                offset=offset,
                bytes_skipped=self.size - offset,
            )
        )

    def _check_data_crc(
        self, arr: U8, p: int, n: int, offset: int, state: _WalkState, damage: DamageLog
    ) -> None:
        if n < 4:
            return
        (stored,) = struct.unpack_from("<I", arr.data, p)
        if stored and stored != state.crc:
            damage.record(
                Defect(
                    Completeness.CHECKSUM_MISMATCH,
                    f"data-section CRC mismatch (stored {stored:#010x}, computed "
                    f"{state.crc:#010x}): some bytes of the data section are damaged",
                    offset=offset,
                )
            )


@dataclass
class _WalkState:
    crc: int
    need: int = 0
    done: bool = False
    pending: _Pending | None = None
    end_at: int = 0  # offset of the DataEnd (or Footer) record that ended the walk


def _parse_chunk_header(
    content: U8, *, partial: bool = False
) -> tuple[int, int, int, int, str, int, int] | None:
    """(start, end, uncompressed size, crc, compression, records offset, records length)."""
    n = len(content)
    if n < 8 + 8 + 8 + 4 + 4:
        return None
    start_t, end_t, usize, crc, clen = struct.unpack_from("<QQQII", content.data, 0)
    at = 32
    if clen > 64 or at + clen + 8 > n:
        return None
    compression = content[at : at + clen].tobytes().decode("ascii", "replace")
    at += clen
    (rec_len,) = struct.unpack_from("<Q", content.data, at)
    at += 8
    if at + rec_len > n:
        if not partial:
            return None
        rec_len = n - at
    if usize > MAX_CHUNK_BYTES:
        return None
    return start_t, end_t, usize, crc, compression, at, rec_len
