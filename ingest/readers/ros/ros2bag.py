"""rosbag2 directories: MCAP storage through ``McapReader``, sqlite3 (and compressed bags)
through rosbags.

- MCAP storage files are read by ``ingest.readers.ros.mcap.McapReader`` (same damage handling,
  same speed). A directory without ``metadata.yaml`` but with MCAP storage is read that way
  too, and the missing metadata is recorded as a recoverable defect (catalogue case 11);
  ``.db3`` storage without metadata is refused by ``ingest.detect``.
- sqlite3 storage and file- or message-compressed bags are read with
  ``rosbags.rosbag2.Reader`` (its row generator costs about what fetching the rows with
  ``sqlite3`` directly costs: measured, so the library is kept); rows are gathered into
  batches and decoded column-wise. SQLite errors ("database disk image is malformed") are
  E-FATAL naming the file (case 12).

Message definitions come from the bag (``message_definitions`` table, MCAP schemas); a bag
without them is decoded with rosbags' standard ROS 2 types, which the report notes.
"""

from __future__ import annotations

import dataclasses
import sqlite3
from collections.abc import Iterator, Sequence
from pathlib import Path
from typing import Any, Literal

import numpy as np

from navreplay.ingest.damage import Completeness, DamageLog, Defect
from navreplay.ingest.detect import MCAP_MAGIC, SQLITE_MAGIC, Detected, Format, has_magic
from navreplay.ingest.errors import CorruptLogError
from navreplay.ingest.readers.base import (
    Batch,
    Inventory,
    LogReader,
    ReadContext,
    Selection,
    StreamInfo,
)
from navreplay.ingest.readers.ros.mcap import McapReader
from navreplay.ingest.readers.ros.roscommon import (
    RosChannel,
    decode_batch,
    make_channel,
    stream_info,
)


class Ros2BagReader(LogReader):
    """Reader of a rosbag2 directory (or its MCAP storage files without metadata.yaml)."""

    format = Format.ROS2BAG

    def __init__(self, detected: Detected, ctx: ReadContext) -> None:
        super().__init__(detected, ctx)
        plain_mcap = detected.variant == "mcap" and all(
            has_magic(f, MCAP_MAGIC) for f in detected.files
        )
        self._parts: list[tuple[McapReader, DamageLog]] = []
        self._known: tuple[list[Any], dict[int, RosChannel], str | None] | None = None
        if plain_mcap:
            for f in detected.files:
                child = DamageLog(f, strict=ctx.damage.strict)
                self._parts.append(
                    (
                        McapReader(dataclasses.replace(detected, files=(f,)), ReadContext(child)),
                        child,
                    )
                )

    def inventory(self) -> Inventory:
        if self._parts:
            return self._merge([part.inventory() for part, _ in self._parts])
        return self._rosbags_inventory()

    def read(self, selections: Sequence[Selection]) -> Iterator[Batch]:
        if self.detected.recovery:
            self.damage.record(Defect(Completeness.MISSING_METADATA, self.detected.recovery))
        if self._parts:
            for part, child in self._parts:
                yield from part.read(selections)
                self._adopt(part.file, child)
            return
        yield from self._rosbags_read(selections)

    # ------------------------------------------------------------------------------ MCAP parts
    def _merge(self, inventories: list[Inventory]) -> Inventory:
        merged: dict[str, StreamInfo] = {}
        for inv in inventories:
            for s in inv.streams:
                prev = merged.get(s.key)
                if prev is None:
                    merged[s.key] = s
                    continue
                merged[s.key] = StreamInfo(
                    key=s.key,
                    msgtype=prev.msgtype,
                    count=None if prev.count is None or s.count is None else prev.count + s.count,
                    start_ns=_min(prev.start_ns, s.start_ns),
                    end_ns=_max(prev.end_ns, s.end_ns),
                    table=prev.table,
                    time_base=prev.time_base,
                    frame=prev.frame,
                    detail=prev.detail,
                )
        notes = [f"{inv.path.name}: {n}" for inv in inventories for n in inv.notes]
        if self.detected.recovery:
            notes.insert(0, self.detected.recovery)
        return Inventory(self.path, self.format, tuple(merged.values()), tuple(notes))

    def _adopt(self, file: Path, child: DamageLog) -> None:
        for d in child.defects:
            self.damage.defects.append(
                Defect(
                    d.kind,
                    f"{file.name}: {d.reason}",
                    d.offset,
                    d.messages_lost,
                    d.messages_recovered,
                    d.time_range_ns,
                    d.bytes_skipped,
                )
            )
        for note in child.notes:
            if note not in self.damage.notes:
                self.damage.notes.append(note)
        for name, n in child.counters.items():
            self.damage.count(name, n)

    # -------------------------------------------------------------------------------- rosbags
    def _open(self) -> Any:
        from rosbags.rosbag2 import Reader

        try:
            reader = Reader(self.path)
            reader.open()
        except Exception as err:  # rosbags raises ReaderError, apsw errors, OSError
            raise CorruptLogError(
                f"rosbag2 bag cannot be opened: {err}",
                path=self.path,
                hint="if SQLite reports a malformed database, recover it outside the pipeline "
                "(sqlite3 .recover) and run `ros2 bag reindex` on the copy",
            ) from err
        return reader

    def _channels(self, reader: Any) -> dict[int, RosChannel]:
        from rosbags.interfaces import MessageDefinitionFormat
        from rosbags.typesys import Stores, get_typestore

        out: dict[int, RosChannel] = {}
        store: Any = None
        for c in reader.connections:
            fmt = c.msgdef.format
            if fmt == MessageDefinitionFormat.NONE:
                store = store or get_typestore(Stores.LATEST)
                try:
                    text = store.generate_msgdef(c.msgtype, ros_version=2)[0]
                except KeyError:
                    text = None
                ch = make_channel(c.topic, c.msgtype, "cdr", text)
                if text is not None:
                    self.damage.note(f"{c.topic}: no definition in the bag; standard ROS 2 type")
            else:
                kind: Literal["msg", "idl"] = "idl" if fmt == MessageDefinitionFormat.IDL else "msg"
                ch = make_channel(c.topic, c.msgtype, "cdr", c.msgdef.data, kind)
            out[c.id] = ch
        return out

    def _rosbags_inventory(self) -> Inventory:
        reader = self._open()
        try:
            channels = self._channels(reader)
            self._known = (list(reader.connections), channels, reader.compression_mode)
            times = self._topic_times()
            streams = []
            for c in reader.connections:
                first, last = times.get(c.topic, (reader.start_time, reader.end_time - 1))
                streams.append(stream_info(channels[c.id], c.msgcount, first, last))
        finally:
            reader.close()
        return Inventory(self.path, self.format, tuple(streams))

    def _topic_times(self) -> dict[str, tuple[int, int]]:
        """Per-topic first/last time from sqlite3 storage (empty for other storage)."""
        out: dict[str, tuple[int, int]] = {}
        for f in self.detected.files:
            if not has_magic(f, SQLITE_MAGIC):
                continue
            try:
                con = sqlite3.connect(f"file:{f}?mode=ro&immutable=1", uri=True)
                try:
                    rows = con.execute(
                        "SELECT topics.name, MIN(timestamp), MAX(timestamp) FROM messages "
                        "JOIN topics ON messages.topic_id = topics.id GROUP BY topics.name"
                    ).fetchall()
                finally:
                    con.close()
            except sqlite3.Error as err:
                raise CorruptLogError(f"SQLite error: {err}", path=f) from err
            for name, lo, hi in rows:
                prev = out.get(name)
                out[name] = (lo, hi) if prev is None else (min(prev[0], lo), max(prev[1], hi))
        return out

    def _rosbags_read(self, selections: Sequence[Selection]) -> Iterator[Batch]:
        keys = {s.key for s in selections}
        if self._known is None:
            self._rosbags_inventory()
        assert self._known is not None
        connections, channels, _compression = self._known
        wanted = [
            c for c in connections if c.topic in keys and channels[c.id].conversion is not None
        ]
        if not wanted:
            return
        reader = self._open()
        try:
            wanted = [c for c in reader.connections if c.id in {w.id for w in wanted}]
            pending: dict[int, tuple[list[bytes], list[int], list[int]]] = {}
            messages = reader.messages(connections=wanted)
            index = 0
            while True:
                try:
                    conn, stamp, raw = next(messages)
                except StopIteration:
                    break
                except Exception as err:  # apsw.Error, ReaderError: the storage is damaged
                    raise CorruptLogError(
                        f"rosbag2 storage read failed after {index} messages: {err}",
                        path=self.path,
                        record=f"message {index}",
                        hint="recover the database outside the pipeline, then "
                        "`ros2 bag reindex` the copy",
                    ) from err
                datas, stamps, ordinals = pending.setdefault(conn.id, ([], [], []))
                datas.append(raw)
                stamps.append(stamp)
                ordinals.append(index)
                index += 1
                if len(datas) >= self.ctx.batch_rows:
                    yield self._batch(channels[conn.id], datas, stamps, ordinals)
                    pending[conn.id] = ([], [], [])
            for cid, (datas, stamps, ordinals) in pending.items():
                if datas:
                    yield self._batch(channels[cid], datas, stamps, ordinals)
        finally:
            reader.close()

    def _batch(
        self, ch: RosChannel, datas: list[bytes], stamps: list[int], ordinals: list[int]
    ) -> Batch:
        lens = np.fromiter(map(len, datas), np.int64, len(datas))
        ends = np.cumsum(lens)
        starts = ends - lens
        buf = np.frombuffer(b"".join(datas), np.uint8)
        # sqlite rows have no byte offset: the message's index in the bag stands in for it.
        return decode_batch(
            self.path,
            ch,
            buf,
            starts,
            ends,
            np.asarray(stamps, np.int64),
            np.asarray(ordinals, np.int64),
            strict=self.damage.strict,
        )


def _min(a: int | None, b: int | None) -> int | None:
    return b if a is None else a if b is None else min(a, b)


def _max(a: int | None, b: int | None) -> int | None:
    return b if a is None else a if b is None else max(a, b)
