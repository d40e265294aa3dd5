"""ROS 1 bags (format 2.0), with uncompressed, bz2 and lz4 chunks.

Reading is a linear scan of the chunk records, so it does not need the index: an unindexed
bag (``index_pos`` 0, a recorder killed before closing: ``.bag.active``) and a truncated bag
are read in full up to the damage, with the defect recorded (catalogue cases 8 and 9). The
input is never modified (``rosbag reindex`` is named as the way to repair a copy).

ROS 1 bags carry no checksums: a chunk whose compression fails to decode (bz2 has block
CRCs) is skipped and counted from the index-data records that follow it; damage inside an
uncompressed chunk cannot be detected, which the report says.

``inventory()`` reads the index section (connection and chunk-info records at
``index_pos``) when the bag has one, and scans the chunks otherwise.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field
from typing import BinaryIO

import numpy as np

from navreplay.ingest.arrays import I64, U8
from navreplay.ingest.damage import Completeness, DamageLog, Defect
from navreplay.ingest.detect import ROSBAG_MAGIC, Detected, Format
from navreplay.ingest.errors import CorruptLogError
from navreplay.ingest.readers._compression import DecompressError, decompress
from navreplay.ingest.readers._walk import BAD_HEADER, INCOMPLETE, OK, TOO_LONG, ros1_records
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
OP_MSG, OP_BAG_HEADER, OP_INDEX, OP_CHUNK, OP_CHUNK_INFO, OP_CONNECTION = 2, 3, 4, 5, 6, 7
_REINDEX = "run `rosbag reindex` on a copy of the bag to rebuild its index"


def parse_header(raw: bytes) -> dict[str, bytes]:
    """Fields ``name=value`` of a record header."""
    out: dict[str, bytes] = {}
    pos = 0
    while pos + 4 <= len(raw):
        (n,) = struct.unpack_from("<I", raw, pos)
        pos += 4
        name, sep, value = raw[pos : pos + n].partition(b"=")
        if not sep or pos + n > len(raw):
            raise ValueError(f"malformed header field at byte {pos - 4}")
        out[name.decode("ascii", "replace")] = value
        pos += n
    return out


@dataclass
class _Segment:
    buf: U8
    dpos: I64
    dlen: I64
    conn: I64
    time_ns: I64
    offsets: I64


@dataclass
class _State:
    index_pos: int = 0
    lost_chunk: tuple[int, str] | None = None
    lost: int = 0
    lost_indexed: bool = False
    counts: dict[int, int] = field(default_factory=dict)


class Ros1BagReader(LogReader):
    """Reader of one ROS 1 bag file."""

    format = Format.ROS1BAG

    def __init__(self, detected: Detected, ctx: ReadContext) -> None:
        super().__init__(detected, ctx)
        self.size = self.file.stat().st_size
        self.channels: dict[int, RosChannel] = {}

    # ----------------------------------------------------------------------------- inventory
    def inventory(self) -> Inventory:
        indexed = self._read_index()
        if indexed is not None:
            return indexed
        scratch = DamageLog(self.file, strict=False)
        counts: dict[int, int] = {}
        first: dict[int, int] = {}
        last: dict[int, int] = {}
        for seg in self._walk(scratch):
            for cid in np.unique(seg.conn).tolist():
                t = seg.time_ns[seg.conn == cid]
                counts[cid] = counts.get(cid, 0) + len(t)
                first[cid] = min(first.get(cid, int(t.min())), int(t.min()))
                last[cid] = max(last.get(cid, int(t.max())), int(t.max()))
        notes = ["no usable index: streams counted by a linear chunk scan"]
        notes += [d.reason for d in scratch.defects]
        return self._inventory_from(counts, first, last, notes)

    def _inventory_from(
        self, counts: dict[int, int], first: dict[int, int], last: dict[int, int], notes: list[str]
    ) -> Inventory:
        by_topic: dict[str, list[int]] = {}
        for cid, ch in sorted(self.channels.items()):
            by_topic.setdefault(ch.key, []).append(cid)
        streams: list[StreamInfo] = []
        for cids in by_topic.values():
            starts = [first[c] for c in cids if c in first]
            ends = [last[c] for c in cids if c in last]
            streams.append(
                stream_info(
                    self.channels[cids[0]],
                    sum(counts.get(c, 0) for c in cids),
                    min(starts) if starts else None,
                    max(ends) if ends else None,
                )
            )
        return Inventory(self.path, self.format, tuple(streams), tuple(notes))

    def _read_index(self) -> Inventory | None:
        """Connections and chunk infos from the index section, or None if it is unusable."""
        with self.file.open("rb") as fh:
            index_pos = self._bag_header(fh)
            if not 0 < index_pos < self.size:
                return None
            fh.seek(index_pos)
            body = fh.read(self.size - index_pos)
        arr = np.frombuffer(body, np.uint8)
        rec, _stop, status, _ = ros1_records(arr, 0, len(body))
        if status != OK or len(rec["op"]) == 0:
            return None
        counts: dict[int, int] = {}
        first: dict[int, int] = {}
        last: dict[int, int] = {}
        try:
            for i, op in enumerate(rec["op"].tolist()):
                h0, hl = int(rec["hpos"][i]), int(rec["hlen"][i])
                d0, dl = int(rec["dpos"][i]), int(rec["dlen"][i])
                header = parse_header(body[h0 : h0 + hl])
                if op == OP_CONNECTION:
                    self._connection(header, body[d0 : d0 + dl])
                elif op == OP_CHUNK_INFO:
                    start = _time(header["start_time"])
                    end = _time(header["end_time"])
                    data = body[d0 : d0 + dl]
                    for k in range(0, len(data) - 7, 8):
                        cid, n = struct.unpack_from("<II", data, k)
                        counts[cid] = counts.get(cid, 0) + n
                        first[cid] = min(first.get(cid, start), start)
                        last[cid] = max(last.get(cid, end), end)
        except (KeyError, ValueError, struct.error):
            self.channels.clear()
            return None
        if not self.channels:
            return None
        return self._inventory_from(
            counts, first, last, ["times from the chunk index (chunk granularity)"]
        )

    def _bag_header(self, fh: BinaryIO) -> int:
        """``index_pos`` from the bag header record (0 if the bag is unindexed)."""
        fh.seek(len(ROSBAG_MAGIC))
        head = fh.read(4096 + 64)
        try:
            (hl,) = struct.unpack_from("<I", head, 0)
            header = parse_header(head[4 : 4 + hl])
            if header.get("op") != bytes([OP_BAG_HEADER]):
                raise ValueError("first record is not the bag header")
            (index_pos,) = struct.unpack("<Q", header["index_pos"])
        except (KeyError, ValueError, struct.error) as err:
            raise CorruptLogError(
                f"bag header record is unreadable: {err}",
                path=self.file,
                offset=len(ROSBAG_MAGIC),
                hint=_REINDEX,
            ) from err
        return int(index_pos)

    def _connection(self, header: dict[str, bytes], data: bytes) -> None:
        (cid,) = struct.unpack("<I", header["conn"])
        if cid in self.channels:
            return
        fields = parse_header(data)
        topic = header.get("topic", fields.get("topic", b"")).decode("utf-8", "replace")
        msgtype = fields.get("type", b"?").decode("utf-8", "replace")
        definition = fields.get("message_definition", b"").decode("utf-8", "replace")
        md5 = fields.get("md5sum", b"").decode("ascii", "replace")
        self.channels[cid] = make_channel(topic, msgtype, "ros1", definition or None, md5sum=md5)

    # ---------------------------------------------------------------------------------- read
    def read(self, selections: Sequence[Selection]) -> Iterator[Batch]:
        keys = {s.key for s in selections}
        self.damage.note(
            "ROS 1 bags carry no checksums: damage inside uncompressed chunks is undetectable"
        )
        for seg in self._walk(self.damage):
            for cid in np.unique(seg.conn).tolist():
                ch = self.channels.get(cid)
                if ch is None:
                    self.damage.count(
                        "messages_on_unknown_connection", int((seg.conn == cid).sum())
                    )
                    continue
                if ch.key not in keys or ch.conversion is None:
                    continue
                sel = np.flatnonzero(seg.conn == cid)
                starts = seg.dpos[sel]
                yield decode_batch(
                    self.file,
                    ch,
                    seg.buf,
                    starts,
                    starts + seg.dlen[sel],
                    seg.time_ns[sel],
                    seg.offsets[sel],
                    strict=self.damage.strict,
                )

    def _walk(self, damage: DamageLog) -> Iterator[_Segment]:
        state = _State()
        with self.file.open("rb") as fh:
            state.index_pos = self._bag_header(fh)
            if state.index_pos == 0:
                damage.record(
                    Defect(
                        Completeness.UNINDEXED,
                        "bag is not indexed (index_pos 0: the recorder did not close it); read by "
                        f"a linear chunk scan ({_REINDEX} if other tools need it)",
                        offset=len(ROSBAG_MAGIC),
                    )
                )
            fh.seek(len(ROSBAG_MAGIC))
            base = len(ROSBAG_MAGIC)
            carry = b""
            need = 0
            while True:
                fresh = fh.read(max(BLOCK_BYTES, need))
                data = carry + fresh if carry else fresh
                at_eof = base + len(data) >= self.size
                arr = np.frombuffer(data, np.uint8)
                rec, stop, status, declared = ros1_records(arr, 0, self.size)
                yield from self._records(arr, base, rec, state, damage)
                if status in (TOO_LONG, BAD_HEADER):
                    self._flush_lost(state, damage)
                    damage.record(
                        Defect(
                            Completeness.CORRUPT_TAIL,
                            f"record at offset {base + stop} has a corrupt "
                            f"{'length' if status == TOO_LONG else 'header'}: nothing after it "
                            "can be framed; every record before it was read",
                            offset=base + stop,
                            bytes_skipped=self.size - base - stop,
                        )
                    )
                    return
                if status == OK and at_eof:
                    break
                if status == INCOMPLETE and at_eof:
                    yield from self._truncated(arr, stop, base, state, damage)
                    return
                carry = data[stop:]
                base += stop
                need = declared - len(carry) if declared > 0 else 0
        self._flush_lost(state, damage)
        if state.index_pos >= self.size:
            damage.record(
                Defect(
                    Completeness.UNINDEXED,
                    f"the file ends before its index section (index_pos {state.index_pos}, "
                    f"{self.size} bytes): every chunk was read by a linear scan ({_REINDEX} "
                    "for other tools)",
                    offset=self.size,
                )
            )

    def _records(
        self,
        arr: U8,
        base: int,
        rec: dict[str, np.ndarray],
        state: _State,
        damage: DamageLog,
    ) -> Iterator[_Segment]:
        for i, op in enumerate(rec["op"].tolist()):
            h0, hl = int(rec["hpos"][i]), int(rec["hlen"][i])
            d0, dl = int(rec["dpos"][i]), int(rec["dlen"][i])
            offset = base + h0 - 4
            if op == OP_CHUNK:
                self._flush_lost(state, damage)
                seg = self._chunk(arr, h0, hl, d0, dl, offset, base, state, partial=False)
                if seg is not None:
                    yield seg
            elif op == OP_INDEX and state.lost_chunk is not None:
                header = parse_header(arr[h0 : h0 + hl].tobytes())
                if "count" in header:
                    state.lost += struct.unpack("<I", header["count"])[0]
                    state.lost_indexed = True
            elif op == OP_CONNECTION:
                self._connection_at(arr, h0, hl, d0, dl, offset)
            elif op == OP_MSG:  # a message outside any chunk (not written by rosbag, but legal)
                yield _Segment(
                    arr,
                    rec["dpos"][i : i + 1],
                    rec["dlen"][i : i + 1],
                    rec["conn"][i : i + 1],
                    rec["time_ns"][i : i + 1],
                    np.array([offset], np.int64),
                )

    def _connection_at(self, arr: U8, h0: int, hl: int, d0: int, dl: int, offset: int) -> None:
        try:
            header = parse_header(arr[h0 : h0 + hl].tobytes())
            self._connection(header, arr[d0 : d0 + dl].tobytes())
        except (KeyError, ValueError, struct.error) as err:
            raise CorruptLogError(
                f"connection record is unreadable: {err}", path=self.file, offset=offset
            ) from err

    def _chunk(
        self,
        arr: U8,
        h0: int,
        hl: int,
        d0: int,
        dl: int,
        offset: int,
        base: int,
        state: _State,
        *,
        partial: bool,
    ) -> _Segment | None:
        try:
            header = parse_header(arr[h0 : h0 + hl].tobytes())
            compression = header["compression"].decode("ascii", "replace")
            (size,) = struct.unpack("<I", header["size"])
        except (KeyError, ValueError, struct.error):
            state.lost_chunk = (offset, "chunk header is malformed")
            return None
        try:
            raw = decompress(compression, arr[d0 : d0 + dl].tobytes(), size, partial=partial)
        except DecompressError as err:
            state.lost_chunk = (offset, f"chunk ({compression}) does not decompress: {err}")
            return None
        buf = np.frombuffer(raw, np.uint8)
        rec, stop, status, _ = ros1_records(buf, 0, len(raw))
        if status != OK and not partial:
            state.lost_chunk = (offset, f"records inside the chunk are malformed at byte {stop}")
            return None
        for i in np.flatnonzero(rec["op"] == OP_CONNECTION).tolist():
            self._connection_at(
                buf,
                int(rec["hpos"][i]),
                int(rec["hlen"][i]),
                int(rec["dpos"][i]),
                int(rec["dlen"][i]),
                offset,
            )
        msg = np.flatnonzero(rec["op"] == OP_MSG)
        if compression == "none":
            offsets = base + d0 + rec["hpos"][msg] - 4
        else:
            offsets = np.full(len(msg), offset, np.int64)
        return _Segment(
            buf, rec["dpos"][msg], rec["dlen"][msg], rec["conn"][msg], rec["time_ns"][msg], offsets
        )

    def _flush_lost(self, state: _State, damage: DamageLog) -> None:
        if state.lost_chunk is None:
            return
        offset, reason = state.lost_chunk
        lost = state.lost if state.lost_indexed else None
        state.lost_chunk, state.lost, state.lost_indexed = None, 0, False
        what = f"{lost} messages lost" if lost is not None else "message count unknown"
        damage.record(
            Defect(
                Completeness.CORRUPT_CHUNKS_SKIPPED,
                f"{reason}: chunk skipped, {what}",
                offset=offset,
                messages_lost=lost,
            )
        )

    def _truncated(
        self, arr: U8, stop: int, base: int, state: _State, damage: DamageLog
    ) -> Iterator[_Segment]:
        self._flush_lost(state, damage)
        offset = base + stop
        recovered = 0
        if 0 < state.index_pos <= offset:
            reason = (
                f"file truncated at offset {self.size}, inside the index section (starting at "
                f"{state.index_pos}): every chunk was read"
            )
        else:
            seg = self._partial_chunk(arr, stop, base, state)
            if seg is not None and len(seg.dpos):
                recovered = len(seg.dpos)
                yield seg
            reason = (
                f"file truncated at offset {self.size}, inside the record starting at {offset}: "
                "every complete chunk before it was read"
                + (f"; {recovered} messages recovered from the cut chunk" if recovered else "")
                + f" ({_REINDEX} for other tools)"
            )
        damage.record(
            Defect(
                Completeness.TRUNCATED,
                reason,
                offset=offset,
                messages_recovered=recovered or None,
                bytes_skipped=self.size - offset,
            )
        )

    def _partial_chunk(self, arr: U8, stop: int, base: int, state: _State) -> _Segment | None:
        if stop + 4 > len(arr):
            return None
        (hl,) = struct.unpack_from("<I", arr.data, stop)
        if stop + 4 + hl + 4 > len(arr):
            return None
        header = arr[stop + 4 : stop + 4 + hl].tobytes()
        try:
            if parse_header(header).get("op") != bytes([OP_CHUNK]):
                return None
        except ValueError:
            return None
        d0 = stop + 8 + hl
        return self._chunk(
            arr, stop + 4, hl, d0, len(arr) - d0, base + stop, base, state, partial=True
        )


def _time(raw: bytes) -> int:
    sec, nsec = struct.unpack("<II", raw)
    return int(sec) * 1_000_000_000 + int(nsec)
