"""Fast serialization of many ROS messages of one fixed layout (IMU, truth at 100 Hz).

rosbags serializes one message object at a time (~10 us each). For a stream whose serialized
layout does not depend on its values (fixed-size fields, a constant ``frame_id``) we let
rosbags serialize one template message whose variable fields hold unique sentinel values, find
the byte offset of each sentinel, and then write all messages at once with numpy. rosbags thus
stays the authority on the layout (CDR alignment, ROS 1 header); if any sentinel is not found
exactly once, we fall back to serializing message by message. Tests check both paths give
identical bytes.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np

# Values unlikely to occur by chance in a serialized message.
_SEC, _NSEC, _SEQ = 1_234_567_891, 987_654_321, 2_023_406_814


class Stream(NamedTuple):
    """One topic's messages.

    Attributes:
        topic: ROS topic.
        msgtype: ROS message type (``sensor_msgs/msg/Imu`` ...).
        stamps_ns: header stamps, ns since the Unix epoch, shape (N,).
        frame_id: header frame.
        values: the per-message float fields, shape (N, K).
        build: (values row (K,), row index, header) -> message object of ``msgtype``.
        fixed: the serialized layout does not depend on the values (enables the fast path).
    """

    topic: str
    msgtype: str
    stamps_ns: np.ndarray
    frame_id: str
    values: np.ndarray
    build: Callable[[np.ndarray, int, Any], Any]
    fixed: bool


def _header(types: Any, ros_version: int, frame: str, t_ns: int, seq: int) -> Any:
    sec, nsec = divmod(int(t_ns), 1_000_000_000)
    stamp = types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec)
    header = types["std_msgs/msg/Header"]
    if ros_version == 1:
        return header(seq=seq, stamp=stamp, frame_id=frame)
    return header(stamp=stamp, frame_id=frame)


def _sentinels(k: int) -> np.ndarray:
    return -7.123456789012345e-289 * (1.0 + np.arange(k) / 7.0)


def _offset(data: bytes, pattern: bytes) -> int | None:
    first = data.find(pattern)
    if first < 0 or data.find(pattern, first + 1) >= 0:
        return None
    return first


def encoder(
    stream: Stream, types: Any, serialize: Callable[[Any, str], Any], ros_version: int
) -> Callable[[int], bytes]:
    """A function giving the serialized bytes of message ``i`` of ``stream``.

    ``serialize`` is the typestore's ``serialize_cdr`` (ROS 2) or ``serialize_ros1``. Fixed
    layouts go through ``bulk_serialize``; others, or when it declines, message by message.
    """
    buf = bulk_serialize(stream, types, serialize, ros_version) if stream.fixed else None
    if buf is not None:
        return lambda i: buf[i].tobytes()

    def one(i: int) -> bytes:
        hdr = _header(types, ros_version, stream.frame_id, stream.stamps_ns[i], i)
        return bytes(serialize(stream.build(stream.values[i], i, hdr), stream.msgtype))

    return one


def bulk_serialize(
    stream: Stream, types: Any, serialize: Callable[[Any, str], Any], ros_version: int
) -> np.ndarray | None:
    """All messages of a fixed-layout stream serialized at once: shape (N, message bytes).

    Returns None when the layout cannot be located unambiguously in the template.
    """
    n, k = stream.values.shape
    marks = _sentinels(k)
    hdr = _header(types, ros_version, stream.frame_id, _SEC * 1_000_000_000 + _NSEC, _SEQ)
    template = bytes(serialize(stream.build(marks, 0, hdr), stream.msgtype))
    le = "<"  # CDR as rosbags writes it (little-endian encapsulation) and ROS 1 alike
    float_at = [_offset(template, np.array(m, dtype=f"{le}f8").tobytes()) for m in marks]
    sec_at = _offset(template, np.array(_SEC, dtype=f"{le}u4").tobytes())
    nsec_at = _offset(template, np.array(_NSEC, dtype=f"{le}u4").tobytes())
    seq_at = _offset(template, np.array(_SEQ, dtype=f"{le}u4").tobytes()) if ros_version == 1 else 0
    if None in float_at or sec_at is None or nsec_at is None or seq_at is None:
        return None
    buf = np.empty((n, len(template)), dtype=np.uint8)
    buf[:] = np.frombuffer(template, dtype=np.uint8)

    def put(offset: int, column: np.ndarray, dtype: str) -> None:
        raw = np.ascontiguousarray(column, dtype=dtype).view(np.uint8).reshape(n, -1)
        buf[:, offset : offset + raw.shape[1]] = raw

    sec, nsec = np.divmod(np.asarray(stream.stamps_ns, dtype=np.int64), 1_000_000_000)
    put(sec_at, sec, f"{le}u4")
    put(nsec_at, nsec, f"{le}u4")
    if ros_version == 1:
        put(seq_at, np.arange(n), f"{le}u4")
    for j, off in enumerate(float_at):
        assert off is not None
        put(off, stream.values[:, j], f"{le}f8")
    return buf
