"""Small ROS logs for tests, written with the formats' own writers (mcap, rosbags).

Messages are built as rosbags message objects and serialized by rosbags (ROS 1 or CDR), so
the readers under test decode bytes produced by an independent implementation.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pytest
from mcap.writer import CompressionType, IndexType, Writer
from rosbags.rosbag1 import Writer as Bag1Writer
from rosbags.rosbag2 import StoragePlugin
from rosbags.rosbag2 import Writer as Bag2Writer
from rosbags.typesys import Stores, get_typestore

from navreplay.ingest.api import ingest
from navreplay.ingest.damage import Completeness, DamageLog, Defect
from navreplay.ingest.detect import detect
from navreplay.ingest.readers import open_reader
from navreplay.ingest.readers.base import ReadContext, Selection
from navreplay.ingest.readers.ros.rosmsg import DefinitionError
from navreplay.ingest.schema import TableName

ROS2 = get_typestore(Stores.ROS2_HUMBLE)
ROS1 = get_typestore(Stores.ROS1_NOETIC)
T0_NS = 1_700_000_000 * 10**9
G = 9.80665

FloatArray = npt.NDArray[np.float64]


def store(ros1: bool) -> Any:
    return ROS1 if ros1 else ROS2


def _stamp(ros1: bool, t_ns: int) -> Any:
    st = store(ros1)
    return st.types["builtin_interfaces/msg/Time"](sec=t_ns // 10**9, nanosec=t_ns % 10**9)


def header(ros1: bool, t_ns: int, frame_id: str, seq: int = 0) -> Any:
    st = store(ros1)
    h = st.types["std_msgs/msg/Header"]
    if ros1:
        return h(seq=seq, stamp=_stamp(ros1, t_ns), frame_id=frame_id)
    return h(stamp=_stamp(ros1, t_ns), frame_id=frame_id)


def vec3(ros1: bool, v: Iterable[float]) -> Any:
    x, y, z = (float(a) for a in v)
    return store(ros1).types["geometry_msgs/msg/Vector3"](x=x, y=y, z=z)


def imu_msg(
    ros1: bool,
    t_ns: int,
    acc: Iterable[float],
    gyro: Iterable[float],
    frame_id: str = "imu_link",
    gyro_cov0: float = 0.0001,
) -> Any:
    st = store(ros1)
    cov = np.zeros(9)
    gcov = np.zeros(9)
    gcov[0] = gyro_cov0
    return st.types["sensor_msgs/msg/Imu"](
        header=header(ros1, t_ns, frame_id),
        orientation=st.types["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
        orientation_covariance=cov.copy(),
        angular_velocity=vec3(ros1, gyro),
        angular_velocity_covariance=gcov,
        linear_acceleration=vec3(ros1, acc),
        linear_acceleration_covariance=cov.copy(),
    )


def navsatfix_msg(
    ros1: bool,
    t_ns: int,
    lat: float,
    lon: float,
    alt: float,
    *,
    status: int = 0,
    cov_diag: tuple[float, float, float] = (1.0, 1.0, 4.0),
    cov_type: int = 2,
) -> Any:
    st = store(ros1)
    cov = np.zeros(9)
    cov[0], cov[4], cov[8] = cov_diag
    return st.types["sensor_msgs/msg/NavSatFix"](
        header=header(ros1, t_ns, "gps"),
        status=st.types["sensor_msgs/msg/NavSatStatus"](status=status, service=1),
        latitude=lat,
        longitude=lon,
        altitude=alt,
        position_covariance=cov,
        position_covariance_type=cov_type,
    )


def odom_msg(ros1: bool, t_ns: int, speed: float, yaw_rate: float) -> Any:
    st = store(ros1)
    t = st.types
    return t["nav_msgs/msg/Odometry"](
        header=header(ros1, t_ns, "odom"),
        child_frame_id="base_link",
        pose=t["geometry_msgs/msg/PoseWithCovariance"](
            pose=t["geometry_msgs/msg/Pose"](
                position=t["geometry_msgs/msg/Point"](x=0.0, y=0.0, z=0.0),
                orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
            ),
            covariance=np.zeros(36),
        ),
        twist=t["geometry_msgs/msg/TwistWithCovariance"](
            twist=t["geometry_msgs/msg/Twist"](
                linear=vec3(ros1, (speed, 0.0, 0.0)), angular=vec3(ros1, (0.0, 0.0, yaw_rate))
            ),
            covariance=np.zeros(36),
        ),
    )


def serialize(ros1: bool, msg: Any) -> bytes:
    st = store(ros1)
    if ros1:
        return bytes(st.serialize_ros1(msg, msg.__msgtype__))
    return bytes(st.serialize_cdr(msg, msg.__msgtype__))


def msgdef(ros1: bool, msgtype: str) -> str:
    st = store(ros1)
    if ros1:
        return str(st.generate_msgdef(msgtype)[0])
    return str(st.generate_msgdef(msgtype, ros_version=2)[0])


@dataclass
class Stream:
    """A topic and its messages: (log time ns, serialized payload)."""

    topic: str
    msgtype: str
    messages: list[tuple[int, bytes]] = field(default_factory=list)
    definition: str | None = None


@dataclass
class ImuData:
    """An IMU series in ROS (FLU) axes: level and at rest unless told otherwise."""

    t_ns: npt.NDArray[np.int64]
    acc: FloatArray
    gyro: FloatArray


def imu_data(n: int, rate_hz: float = 100.0, *, seed: int = 0, t0_ns: int = T0_NS) -> ImuData:
    rng = np.random.default_rng(seed)
    t = t0_ns + np.round(np.arange(n) * 1e9 / rate_hz).astype(np.int64)
    acc = np.array([0.0, 0.0, G]) + rng.normal(0.0, 0.02, (n, 3))
    gyro = np.array([0.001, -0.002, 0.0005]) + rng.normal(0.0, 0.001, (n, 3))
    return ImuData(t, acc, gyro)


def imu_stream(
    data: ImuData, *, ros1: bool = False, topic: str = "/imu/data", frame_id: str = "imu_link"
) -> Stream:
    s = Stream(topic, "sensor_msgs/msg/Imu")
    for t, a, g in zip(data.t_ns.tolist(), data.acc, data.gyro, strict=True):
        s.messages.append((t, serialize(ros1, imu_msg(ros1, t, a, g, frame_id))))
    return s


def fix_stream(
    n: int,
    rate_hz: float = 5.0,
    *,
    ros1: bool = False,
    topic: str = "/fix",
    t0_ns: int = T0_NS,
    lat0: float = 37.5,
    lon0: float = 127.0,
) -> Stream:
    s = Stream(topic, "sensor_msgs/msg/NavSatFix")
    for i in range(n):
        t = t0_ns + round(i * 1e9 / rate_hz)
        msg = navsatfix_msg(ros1, t, lat0 + 1e-6 * i, lon0 + 2e-6 * i, 50.0 + 0.01 * i)
        s.messages.append((t, serialize(ros1, msg)))
    return s


def odom_stream(n: int, rate_hz: float = 10.0, *, ros1: bool = False, t0_ns: int = T0_NS) -> Stream:
    s = Stream("/odom", "nav_msgs/msg/Odometry")
    for i in range(n):
        t = t0_ns + round(i * 1e9 / rate_hz)
        s.messages.append((t, serialize(ros1, odom_msg(ros1, t, 1.0 + 0.01 * i, 0.1))))
    return s


def _merged(streams: list[Stream]) -> list[tuple[int, int, bytes]]:
    out = [(t, k, data) for k, s in enumerate(streams) for t, data in s.messages]
    out.sort(key=lambda e: (e[0], e[1]))
    return out


def write_mcap(
    path: Path,
    streams: list[Stream],
    *,
    ros1: bool = False,
    compression: CompressionType = CompressionType.ZSTD,
    chunk_size: int = 16 * 1024,
    use_chunking: bool = True,
    index_types: IndexType = IndexType.ALL,
    finish: bool = True,
) -> Path:
    """An MCAP file (ROS 1 or ROS 2 profile) with the streams' messages in log-time order."""
    with path.open("wb") as fh:
        w = Writer(
            fh,
            chunk_size=chunk_size,
            compression=compression,
            use_chunking=use_chunking,
            index_types=index_types,
        )
        w.start(profile="ros1" if ros1 else "ros2", library="navreplay-tests")
        ids = []
        for s in streams:
            text = s.definition if s.definition is not None else msgdef(ros1, s.msgtype)
            name = s.msgtype.replace("/msg/", "/") if ros1 else s.msgtype
            schema = w.register_schema(name, "ros1msg" if ros1 else "ros2msg", text.encode())
            ids.append(w.register_channel(s.topic, "ros1" if ros1 else "cdr", schema))
        for seq, (t, k, data) in enumerate(_merged(streams)):
            w.add_message(ids[k], log_time=t, data=data, publish_time=t, sequence=seq)
        if finish:
            w.finish()  # type: ignore[no-untyped-call]
    return path


def write_bag1(
    path: Path,
    streams: list[Stream],
    *,
    compression: str | None = None,
    chunk_threshold: int = 16 * 1024,
) -> Path:
    """A ROS 1 bag through rosbags' writer (``compression``: None, ``bz2`` or ``lz4``)."""
    w = Bag1Writer(path)
    if compression is not None:
        w.set_compression(getattr(Bag1Writer.CompressionFormat, compression.upper()))
    w.chunk_threshold = chunk_threshold
    with w:
        conns = [
            w.add_connection(
                s.topic,
                s.msgtype,
                typestore=ROS1,
                msgdef=s.definition,
                md5sum=None if s.definition is None else "*",
            )
            for s in streams
        ]
        for t, k, data in _merged(streams):
            w.write(conns[k], t, data)
    return path


def write_bag2(
    path: Path, streams: list[Stream], *, version: int = 9, storage: str = "sqlite3"
) -> Path:
    """A rosbag2 directory through rosbags' writer (``storage``: ``sqlite3`` or ``mcap``)."""
    plugin = StoragePlugin.SQLITE3 if storage == "sqlite3" else StoragePlugin.MCAP
    with Bag2Writer(path, version=version, storage_plugin=plugin) as w:  # type: ignore[arg-type]
        conns = [w.add_connection(s.topic, s.msgtype, typestore=ROS2) for s in streams]
        for t, k, data in _merged(streams):
            w.write(conns[k], t, data)
    return path


def imu_payloads(ros1: bool, data: ImuData) -> npt.NDArray[np.uint8]:
    """Serialized Imu messages for a whole series at once, one row per message.

    One template is serialized by rosbags; the stamps and vectors are then written into a
    tiled copy at the byte positions rosbags used (found from marker values), so large logs
    cost numpy time, not per-message serialization.
    """
    markers = (1234.5, 2345.5, 3456.5, 4567.5, 5678.5, 6789.5)
    template = serialize(
        ros1, imu_msg(ros1, 0x7F0F0F0F * 10**9 + 0x0F0E0D0C, markers[3:], markers[:3])
    )
    raw = np.frombuffer(template, np.uint8)
    rows = np.tile(raw, (len(data.t_ns), 1))
    sec_at = template.find((0x7F0F0F0F).to_bytes(4, "little"))
    rows[:, sec_at : sec_at + 4] = (data.t_ns // 10**9).astype("<u4").view(np.uint8).reshape(-1, 4)
    rows[:, sec_at + 4 : sec_at + 8] = (
        (data.t_ns % 10**9).astype("<u4").view(np.uint8).reshape(-1, 4)
    )
    values = np.concatenate([data.gyro, data.acc], axis=1)
    for k, marker in enumerate(markers):
        at = template.find(np.float64(marker).tobytes())
        rows[:, at : at + 8] = values[:, k].astype("<f8").view(np.uint8).reshape(-1, 8)
    return rows


def write_imu_mcap_fast(
    path: Path, n: int, *, rate_hz: float = 400.0, seed: int = 0, chunk_size: int = 1 << 20
) -> Path:
    """A large ROS 2 MCAP of small IMU messages through ``mcap.writer.Writer``."""
    data = imu_data(n, rate_hz, seed=seed)
    rows = imu_payloads(False, data)
    with path.open("wb") as fh:
        w = Writer(fh, chunk_size=chunk_size, compression=CompressionType.ZSTD)
        w.start(profile="ros2", library="navreplay-tests")
        schema = w.register_schema(
            "sensor_msgs/msg/Imu", "ros2msg", msgdef(False, "sensor_msgs/msg/Imu").encode()
        )
        ch = w.register_channel("/imu/data", "cdr", schema)
        for t, row in zip(data.t_ns.tolist(), rows, strict=True):
            w.add_message(ch, log_time=t, data=row.tobytes(), publish_time=t)
        w.finish()  # type: ignore[no-untyped-call]
    return path


def read_imu(path: Path, *, strict: bool = False) -> tuple[dict[str, np.ndarray], DamageLog]:
    """The ``/imu/data`` stream of a ROS log (its reader found by its detected format) as
    whole columns, and the damage log of the read."""
    damage = DamageLog(path, strict=strict)
    reader = open_reader(detect(path), ReadContext(damage))
    parts = list(reader.read([Selection("/imu/data", TableName.IMU)]))
    cols = (
        {k: np.concatenate([b.columns[k] for b in parts]) for k in parts[0].columns}
        if parts
        else {}
    )
    return cols, damage


def assert_imu_reads_back(path: Path, data: ImuData) -> None:
    """The ``/imu/data`` stream of the ROS log at ``path`` holds ``data`` exactly (in the
    source, FLU, axes: the sink converts), and the read found the log complete."""
    cols, damage = read_imu(path)
    np.testing.assert_array_equal(cols["t_ns"], data.t_ns)
    for i, axis in enumerate("xyz"):
        np.testing.assert_array_equal(cols[f"acc_{axis}_mps2"], data.acc[:, i])
        np.testing.assert_array_equal(cols[f"gyro_{axis}_radps"], data.gyro[:, i])
    assert damage.completeness == ["complete"]


def read_truncated(
    path: Path, original: bytes, data: ImuData, stream: Stream
) -> tuple[int, Defect]:
    """Read ``path``, the log ``original`` cut short, and check that exactly the IMU messages
    of ``stream`` (``data``) lying wholly before the cut come back; returns their count and
    the truncation defect."""
    cut = path.stat().st_size
    complete = sum(original.find(p) + len(p) <= cut for _, p in stream.messages)
    cols, damage = read_imu(path)
    assert len(cols["t_ns"]) == complete
    np.testing.assert_array_equal(cols["t_ns"], data.t_ns[:complete])
    (defect,) = damage.defects
    assert defect.kind == Completeness.TRUNCATED
    assert defect.offset is not None
    assert 0 < defect.offset < cut
    return complete, defect


def assert_definition_mismatch_is_fatal(path: Path, out: Path) -> None:
    """Ingesting ``path`` stops at the ``/imu/data`` definition that does not describe its
    payloads, naming the file, the topic and an offset, and writes nothing."""
    with pytest.raises(DefinitionError) as err:
        ingest([path], out)
    text = str(err.value)
    assert "definition mismatch" in text
    assert str(path) in text
    assert "/imu/data" in text
    assert err.value.offset is not None
    assert not out.exists()
