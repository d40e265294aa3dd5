"""What the MCAP, ROS 1 bag and rosbag2 readers share: a decoded ROS channel and its batches."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np

from navreplay.ingest.arrays import I64, U8
from navreplay.ingest.errors import CorruptLogError
from navreplay.ingest.readers.base import Batch, StreamInfo
from navreplay.ingest.readers.ros.rosconv import RosConversion, conversion_for
from navreplay.ingest.readers.ros.rosmsg import (
    DefinitionError,
    Encoding,
    MessageDecoder,
    normalize_msgtype,
    parse_definition,
)
from navreplay.ingest.schema import TableName
from navreplay.ingest.timebase import MIN_PLAUSIBLE_UTC_NS, TimeBase


@dataclass
class RosChannel:
    """A ROS topic (or one MCAP channel of it) with its decoder and conversion.

    Attributes:
        key: the topic.
        msgtype: normalized type name (``sensor_msgs/msg/Imu``).
        encoding: ``ros1`` or ``cdr``.
        decoder: None when the definition is missing or does not parse (see ``problem``).
        conversion: None when the type feeds no canonical table.
        problem: why the channel cannot be decoded, for ``--list`` and errors.
    """

    key: str
    msgtype: str
    encoding: Encoding
    decoder: MessageDecoder | None
    conversion: RosConversion | None
    problem: str | None = None
    decoded_ok: int = 0
    malformed: int = 0

    @property
    def table(self) -> TableName | None:
        return self.conversion.table if self.conversion else None


def make_channel(
    topic: str,
    msgtype: str,
    encoding: str,
    definition: str | None,
    fmt: Literal["msg", "idl"] = "msg",
    *,
    md5sum: str | None = None,
) -> RosChannel:
    """Parse a channel's definition and find its conversion; never raises for a bad one.

    ``md5sum`` (ROS 1 connections) is checked against the md5 of the parsed definition: a
    mismatch means the definition does not describe what was published (catalogue case 20).
    """
    name = normalize_msgtype(msgtype)
    if encoding not in ("ros1", "cdr"):
        return RosChannel(topic, name, "cdr", None, None, f"unsupported encoding {encoding!r}")
    enc: Encoding = "ros1" if encoding == "ros1" else "cdr"
    if not definition:
        return RosChannel(topic, name, enc, None, None, "no message definition in the log")
    try:
        decoder = MessageDecoder(name, parse_definition(name, definition, fmt), enc)
    except DefinitionError as err:
        return RosChannel(topic, name, enc, None, None, err.reason)
    if md5sum and md5sum != "*" and (have := _ros1_md5(decoder)) not in (None, md5sum):
        return RosChannel(
            topic,
            name,
            enc,
            None,
            None,
            f"definition mismatch: md5 of the embedded definition is {have}, the connection "
            f"declares {md5sum}",
        )
    conversion, problem = conversion_for(decoder, topic)
    return RosChannel(topic, name, enc, decoder, conversion, problem)


def _ros1_md5(decoder: MessageDecoder) -> str | None:
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.EMPTY)
    try:
        store.register(decoder.types)
        return str(store.generate_msgdef(decoder.msgtype)[1])
    except Exception:
        return None


def time_base_of(log_ns: int | None) -> TimeBase:
    """ROS stamps are wall-clock UTC unless the recording ran on simulated/boot time."""
    if log_ns is not None and log_ns < MIN_PLAUSIBLE_UTC_NS:
        return TimeBase.RECORDER
    return TimeBase.UTC


def stream_info(
    channel: RosChannel, count: int | None, start_ns: int | None, end_ns: int | None
) -> StreamInfo:
    detail = channel.encoding if channel.problem is None else f"not decodable: {channel.problem}"
    if channel.decoder is not None and not channel.decoder.vectorised:
        detail += " (per-message decoder)"
    return StreamInfo(
        key=channel.key,
        msgtype=channel.msgtype,
        count=count,
        start_ns=start_ns,
        end_ns=end_ns,
        table=channel.table,
        time_base=time_base_of(start_ns),
        frame=channel.conversion.frame if channel.conversion else None,
        detail=detail,
        role=channel.conversion.role if channel.conversion else "",
    )


# A topic whose first this-many payloads all fail is taken as a definition mismatch at once.
MISMATCH_AFTER = 16


def decode_batch(
    path: Path,
    channel: RosChannel,
    buf: U8,
    starts: I64,
    ends: I64,
    log_ns: I64,
    offsets: I64,
    *,
    strict: bool = False,
) -> Batch:
    """Decode the payloads ``buf[starts:ends]`` of ``channel`` into a canonical batch.

    A payload that does not fit the definition (empty, cut, too long: catalogue case 22) is
    dropped and counted (``payloads_malformed_dropped``); when no payload of the topic fits,
    the definition itself is wrong (case 20).

    Raises:
        DefinitionError: the first ``MISMATCH_AFTER`` payloads of the topic all fail to fit
            (E-FATAL for the topic), naming the file, the record offset and the topic; the
            caller checks a topic that ends with no payload fitting the same way.
        CorruptLogError: a malformed payload under ``--strict``.
    """
    conv = channel.conversion
    assert conv is not None
    assert channel.decoder is not None
    decoded = channel.decoder.decode(buf, starts, ends, conv.wants)
    out = conv.convert(decoded, log_ns)
    columns, nulls, counters = out.columns, out.nulls, dict(out.counters)
    info = dict(out.info)
    bad = decoded.bad
    if bad is not None:
        first = int(offsets[int(np.flatnonzero(bad)[0])])
        channel.malformed += int(bad.sum())
        where = f"topic {channel.key} ({channel.msgtype}, {channel.encoding})"
        if channel.decoded_ok == 0 and channel.malformed >= MISMATCH_AFTER:
            raise mismatch_error(path, channel, first, decoded.reason)
        if strict:
            raise CorruptLogError(
                f"malformed payload: {decoded.reason}",
                path=path,
                offset=first,
                record=where,
                hint="--strict refuses malformed payloads; without it they are dropped and counted",
            )
        keep = ~bad
        columns = {k: v[keep] for k, v in columns.items()}
        nulls = {k: v[keep] for k, v in nulls.items()}
        offsets = offsets[keep]
        counters["payloads_malformed_dropped"] = int(bad.sum())
        info["first_malformed_payload"] = f"offset {first}: {decoded.reason}"
    channel.decoded_ok += len(offsets)
    frame = conv.frame
    if conv.frame == "flu" and info.get("frame_id", "").rstrip("/").lower().endswith("_ned"):
        frame = "frd"
    return Batch(
        key=channel.key,
        table=conv.table,
        columns=columns,
        offsets=offsets,
        nulls=nulls,
        frame=frame,
        counters=counters,
        info=info,
    )


def mismatch_error(
    path: Path, channel: RosChannel, offset: int | None, reason: str
) -> DefinitionError:
    """The E-FATAL error for a topic whose payloads do not fit its definition (case 20)."""
    return DefinitionError(
        f"definition mismatch: none of the first {channel.malformed} payloads fits "
        f"{channel.msgtype} as defined in the log ({reason})",
        path=path,
        offset=offset,
        record=f"topic {channel.key} ({channel.msgtype}, {channel.encoding})",
        hint="the log's message definition does not describe its payloads; exclude the topic "
        "or fix the definition",
    )
