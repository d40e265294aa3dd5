"""Canonical tables -> ROS 2 MCAP and ROS 1 bag files, as a ROS driver stack would record them.

Topics (``RosTopics``):

- ``/imu/data`` ``sensor_msgs/Imu``: body FLU per REP-103 (the canonical FRD axes y and z
  negated); orientation unknown (``orientation_covariance[0] = -1``, REP-145); the diagonal
  covariances are the per-sample white-noise variances when given.
- ``/gps/fix`` ``sensor_msgs/NavSatFix``: WGS-84 latitude, longitude and ellipsoidal altitude;
  ``position_covariance`` ENU diagonal ``[h_acc^2, h_acc^2, v_acc^2]`` (DIAGONAL_KNOWN);
  status NO_FIX (-1) where the fix is invalid.
- ``/gps/vel`` ``geometry_msgs/TwistWithCovarianceStamped``: fix velocity in ENU
  (``linear = [vel_e, vel_n, -vel_d]``), linear covariance ``speed_acc^2``; angular unused (0).
- ``/truth`` ``navreplay_msgs/msg/NavTruth``: ``std_msgs/Header header`` plus one ``float64``
  field per float column of the truth table, named exactly as the column (``lat_deg`` ...
  ``clock_drift_mps``). Its definition is embedded in the file, so readers decode it from the
  file alone; readers map truth topics back to columns by field name.

Header stamps and log times are UTC nanoseconds since the Unix epoch, as a ROS system records:
tables on the GPS time base are shifted by the GPS-UTC leap seconds. CDR (ROS 2) and ROS 1
serialization are rosbags'; the MCAP container is written with the ``mcap`` library (zstd
chunks, ``ros2msg`` schemas), the bag with ``rosbags.rosbag1`` (LZ4 chunks). Output is
deterministic: the same tables give byte-identical files.
"""

from __future__ import annotations

import heapq
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import numpy as np
import pyarrow as pa
from mcap.writer import CompressionType
from mcap.writer import Writer as McapWriter
from rosbags.rosbag1 import Writer as Bag1Writer
from rosbags.typesys import Stores, get_types_from_msg, get_typestore
from rosbags.typesys.store import Typestore

from ingest.atomic import atomic_path
from ingest.gpstime import NS_PER_S, utc_unix_ns_from_gps
from ingest.tables import package_version

TRUTH_MSGTYPE = "navreplay_msgs/msg/NavTruth"
_IMU, _FIX = "sensor_msgs/msg/Imu", "sensor_msgs/msg/NavSatFix"
_VEL = "geometry_msgs/msg/TwistWithCovarianceStamped"
_STATUS_FIX, _STATUS_NO_FIX, _SERVICE_GPS, _COV_DIAGONAL_KNOWN = 0, -1, 1, 2


@dataclass(frozen=True)
class RosTopics:
    """Topic and frame names."""

    imu: str = "/imu/data"
    fix: str = "/gps/fix"
    vel: str = "/gps/vel"
    truth: str = "/truth"
    imu_frame: str = "imu_link"
    gnss_frame: str = "gps_link"
    truth_frame: str = "imu_link"


@dataclass(frozen=True)
class RosOptions:
    """How to write.

    Attributes:
        topics: topic and frame names.
        time_base: the tables' time base; ``gps`` is converted to UTC stamps.
        accel_var_m2ps4: per-sample accelerometer noise variance for the IMU covariance.
        gyro_var_rad2ps2: per-sample gyro noise variance.
    """

    topics: RosTopics = RosTopics()
    time_base: Literal["gps", "utc"] = "gps"
    accel_var_m2ps4: float = 0.0
    gyro_var_rad2ps2: float = 0.0


def truth_msgdef(truth: pa.Table) -> str:
    """The ``NavTruth`` message definition for a truth table (its float columns, in order)."""
    names = [f.name for f in truth.schema if f.name != "t_ns"]
    return "std_msgs/Header header\n" + "".join(f"float64 {n}\n" for n in names)


def typestore(ros_version: Literal[1, 2], truth: pa.Table | None) -> Typestore:
    """A fresh typestore of ROS 1 Noetic or ROS 2 Humble, with ``NavTruth`` registered."""
    store = get_typestore(Stores.ROS1_NOETIC if ros_version == 1 else Stores.ROS2_HUMBLE)
    if truth is not None:
        store.register(get_types_from_msg(truth_msgdef(truth), TRUTH_MSGTYPE))
    return store


def _stamps(t_ns: np.ndarray, time_base: str) -> np.ndarray:
    t = np.asarray(t_ns, dtype=np.int64)
    return utc_unix_ns_from_gps(t) if time_base == "gps" else t


def _col(table: pa.Table, name: str) -> np.ndarray:
    """A float column as numpy with nulls as NaN."""
    return np.asarray(table.column(name).to_numpy(zero_copy_only=False), dtype=np.float64)


_Stream = tuple[str, str, np.ndarray, Callable[[int, Any], Any]]


def _streams(
    tables: Mapping[str, pa.Table], store: Typestore, opts: RosOptions, ros_version: int
) -> list[_Stream]:
    """(topic, msgtype, stamps, make(i, header) -> message) for each table present."""
    T = store.types
    tp = opts.topics
    Vec, Quat = T["geometry_msgs/msg/Vector3"], T["geometry_msgs/msg/Quaternion"]
    out: list[_Stream] = []
    if "imu" in tables:
        imu = tables["imu"]
        a = np.stack([_col(imu, f"acc_{k}_mps2") for k in "xyz"], axis=-1) * [1.0, -1.0, -1.0]
        w = np.stack([_col(imu, f"gyro_{k}_radps") for k in "xyz"], axis=-1) * [1.0, -1.0, -1.0]
        ocov = np.zeros(9)
        ocov[0] = -1.0
        acov, gcov = (
            np.eye(3).ravel() * opts.accel_var_m2ps4,
            np.eye(3).ravel() * opts.gyro_var_rad2ps2,
        )
        quat = Quat(x=0.0, y=0.0, z=0.0, w=1.0)

        def make_imu(i: int, hdr: Any) -> Any:
            return T[_IMU](
                header=hdr,
                orientation=quat,
                orientation_covariance=ocov,
                angular_velocity=Vec(x=w[i, 0], y=w[i, 1], z=w[i, 2]),
                angular_velocity_covariance=gcov,
                linear_acceleration=Vec(x=a[i, 0], y=a[i, 1], z=a[i, 2]),
                linear_acceleration_covariance=acov,
            )

        out.append((tp.imu, _IMU, imu.column("t_ns").to_numpy(), make_imu))
    if "gnss" in tables:
        out.extend(_gnss_streams(tables["gnss"], T, tp))
    if "truth" in tables:
        truth = tables["truth"]
        names = [f.name for f in truth.schema if f.name != "t_ns"]
        cols = np.stack([_col(truth, n) for n in names], axis=-1)

        def make_truth(i: int, hdr: Any) -> Any:
            return T[TRUTH_MSGTYPE](hdr, *cols[i].tolist())

        out.append((tp.truth, TRUTH_MSGTYPE, truth.column("t_ns").to_numpy(), make_truth))
    return out


def _gnss_streams(gnss: pa.Table, T: Mapping[str, Any], tp: RosTopics) -> list[_Stream]:
    lat, lon, alt = _col(gnss, "lat_deg"), _col(gnss, "lon_deg"), _col(gnss, "alt_m")
    h_acc, v_acc = _col(gnss, "h_acc_m"), _col(gnss, "v_acc_m")
    vel = np.stack([_col(gnss, f"vel_{k}_mps") for k in "ned"], axis=-1)
    s_acc = (
        _col(gnss, "speed_acc_mps")
        if "speed_acc_mps" in gnss.column_names
        else np.full(gnss.num_rows, np.nan)
    )
    fix_ok = np.isfinite(lat) & np.isfinite(lon) & (gnss.column("fix_type").to_numpy() >= 2)
    Status, Vec = T["sensor_msgs/msg/NavSatStatus"], T["geometry_msgs/msg/Vector3"]
    Twist, TwistCov = T["geometry_msgs/msg/Twist"], T["geometry_msgs/msg/TwistWithCovariance"]
    zero = Vec(x=0.0, y=0.0, z=0.0)
    ok, bad = (
        Status(status=_STATUS_FIX, service=_SERVICE_GPS),
        Status(status=_STATUS_NO_FIX, service=_SERVICE_GPS),
    )

    def make_fix(i: int, hdr: Any) -> Any:
        cov = np.zeros(9)
        cov[0], cov[4], cov[8] = h_acc[i] ** 2, h_acc[i] ** 2, v_acc[i] ** 2
        return T[_FIX](
            header=hdr,
            status=ok if fix_ok[i] else bad,
            latitude=lat[i],
            longitude=lon[i],
            altitude=alt[i],
            position_covariance=cov,
            position_covariance_type=_COV_DIAGONAL_KNOWN,
        )

    def make_vel(i: int, hdr: Any) -> Any:
        cov = np.zeros(36)
        cov[0] = cov[7] = cov[14] = s_acc[i] ** 2
        lin = Vec(x=vel[i, 1], y=vel[i, 0], z=-vel[i, 2])
        return T[_VEL](
            header=hdr, twist=TwistCov(twist=Twist(linear=lin, angular=zero), covariance=cov)
        )

    t = gnss.column("t_ns").to_numpy()
    out: list[_Stream] = [(tp.fix, _FIX, t, make_fix)]
    if not np.all(np.isnan(vel)):
        out.append((tp.vel, _VEL, t, make_vel))
    return out


def _frame(topic: str, tp: RosTopics) -> str:
    if topic == tp.imu:
        return tp.imu_frame
    if topic in (tp.fix, tp.vel):
        return tp.gnss_frame
    return tp.truth_frame


def _keyed(stamps: np.ndarray, k: int) -> Iterator[tuple[int, int, int]]:
    return ((int(t), k, i) for i, t in enumerate(stamps.tolist()))


def _merged(
    streams: list[_Stream], store: Typestore, opts: RosOptions, ros_version: int
) -> Iterator[tuple[int, int, Any]]:
    """(stream index, stamp ns, message) of all streams in time order (ties: stream order)."""
    Header, Time = store.types["std_msgs/msg/Header"], store.types["builtin_interfaces/msg/Time"]
    stamps = [_stamps(s[2], opts.time_base) for s in streams]
    frames = [_frame(s[0], opts.topics) for s in streams]
    order = heapq.merge(*(_keyed(st, k) for k, st in enumerate(stamps)))
    for t, k, i in order:
        sec, nsec = divmod(t, NS_PER_S)
        stamp = Time(sec=sec, nanosec=nsec)
        hdr = (
            Header(seq=i, stamp=stamp, frame_id=frames[k])
            if ros_version == 1
            else Header(stamp=stamp, frame_id=frames[k])
        )
        yield k, t, streams[k][3](i, hdr)


def write_mcap(path: str | Path, tables: Mapping[str, pa.Table], opts: RosOptions) -> None:
    """Write the tables as a ROS 2 MCAP file (CDR messages, ``ros2msg`` schemas), atomically."""
    store = typestore(2, tables.get("truth"))
    streams = _streams(tables, store, opts, 2)
    with atomic_path(path) as tmp, tmp.open("wb") as fh:
        writer = McapWriter(fh, compression=CompressionType.ZSTD, chunk_size=1 << 20)
        writer.start(profile="ros2", library=f"navreplay {package_version()}")
        channels = []
        for topic, msgtype, _, _ in streams:
            schema = writer.register_schema(
                name=msgtype,
                encoding="ros2msg",
                data=store.generate_msgdef(msgtype, ros_version=2)[0].encode(),
            )
            channels.append(
                writer.register_channel(topic=topic, message_encoding="cdr", schema_id=schema)
            )
        seq = [0] * len(streams)
        for k, t, msg in _merged(streams, store, opts, 2):
            data = store.serialize_cdr(msg, streams[k][1])
            writer.add_message(
                channels[k], log_time=t, data=bytes(data), publish_time=t, sequence=seq[k]
            )
            seq[k] += 1
        writer.finish()  # type: ignore[no-untyped-call]


def write_bag(path: str | Path, tables: Mapping[str, pa.Table], opts: RosOptions) -> None:
    """Write the tables as a ROS 1 bag (v2.0, LZ4-compressed chunks), atomically."""
    store = typestore(1, tables.get("truth"))
    streams = _streams(tables, store, opts, 1)
    with atomic_path(path) as tmp:
        bag = Bag1Writer(tmp)
        bag.set_compression(Bag1Writer.CompressionFormat.LZ4)
        with bag:
            conns = [
                bag.add_connection(topic, msgtype, typestore=store)
                for topic, msgtype, _, _ in streams
            ]
            for k, t, msg in _merged(streams, store, opts, 1):
                bag.write(conns[k], t, store.serialize_ros1(msg, streams[k][1]))
