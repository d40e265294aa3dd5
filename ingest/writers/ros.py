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
serialization are rosbags' (``ingest.writers.rosserial`` replicates a rosbags-serialized
template for the high-rate fixed-layout streams); the MCAP container is written with the
``mcap`` library (zstd chunks, ``ros2msg`` schemas), the bag with ``rosbags.rosbag1`` (LZ4
chunks). Output is deterministic: the same tables give byte-identical files.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
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

from navreplay.ingest.atomic import atomic_path
from navreplay.ingest.gpstime import utc_unix_ns_from_gps
from navreplay.ingest.tables import package_version
from navreplay.ingest.writers.rosserial import Stream, encoder

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


def _streams(tables: Mapping[str, pa.Table], store: Typestore, opts: RosOptions) -> list[Stream]:
    """The ROS streams of the tables present, in a fixed topic order."""
    T = store.types
    tp = opts.topics
    out: list[Stream] = []
    if "imu" in tables:
        out.append(_imu_stream(tables["imu"], T, opts))
    if "gnss" in tables:
        out.extend(_gnss_streams(tables["gnss"], T, opts))
    if "truth" in tables:
        truth = tables["truth"]
        names = [f.name for f in truth.schema if f.name != "t_ns"]
        cols = np.stack([_col(truth, n) for n in names], axis=-1)

        def make_truth(v: np.ndarray, i: int, hdr: Any) -> Any:
            return T[TRUTH_MSGTYPE](hdr, *v.tolist())

        stamps = _stamps(truth.column("t_ns").to_numpy(), opts.time_base)
        out.append(Stream(tp.truth, TRUTH_MSGTYPE, stamps, tp.truth_frame, cols, make_truth, True))
    return out


def _imu_stream(imu: pa.Table, T: Mapping[str, Any], opts: RosOptions) -> Stream:
    flu = np.array([1.0, -1.0, -1.0])
    a = np.stack([_col(imu, f"acc_{k}_mps2") for k in "xyz"], axis=-1) * flu
    w = np.stack([_col(imu, f"gyro_{k}_radps") for k in "xyz"], axis=-1) * flu
    ocov = np.zeros(9)
    ocov[0] = -1.0
    acov = np.eye(3).ravel() * opts.accel_var_m2ps4
    gcov = np.eye(3).ravel() * opts.gyro_var_rad2ps2
    Vec = T["geometry_msgs/msg/Vector3"]
    quat = T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)

    def make_imu(v: np.ndarray, i: int, hdr: Any) -> Any:
        return T[_IMU](
            header=hdr,
            orientation=quat,
            orientation_covariance=ocov,
            angular_velocity=Vec(x=v[3], y=v[4], z=v[5]),
            angular_velocity_covariance=gcov,
            linear_acceleration=Vec(x=v[0], y=v[1], z=v[2]),
            linear_acceleration_covariance=acov,
        )

    stamps = _stamps(imu.column("t_ns").to_numpy(), opts.time_base)
    values = np.concatenate([a, w], axis=1)
    return Stream(opts.topics.imu, _IMU, stamps, opts.topics.imu_frame, values, make_imu, True)


def _gnss_streams(gnss: pa.Table, T: Mapping[str, Any], opts: RosOptions) -> list[Stream]:
    tp = opts.topics
    pos = np.stack([_col(gnss, n) for n in ("lat_deg", "lon_deg", "alt_m")], axis=-1)
    acc = np.stack([_col(gnss, "h_acc_m"), _col(gnss, "v_acc_m")], axis=-1)
    vel = np.stack([_col(gnss, f"vel_{k}_mps") for k in "ned"], axis=-1)
    s_acc = (
        _col(gnss, "speed_acc_mps")
        if "speed_acc_mps" in gnss.column_names
        else np.full(gnss.num_rows, np.nan)
    )
    fix_ok = np.isfinite(pos[:, :2]).all(axis=1) & (gnss.column("fix_type").to_numpy() >= 2)
    Status, Vec = T["sensor_msgs/msg/NavSatStatus"], T["geometry_msgs/msg/Vector3"]
    Twist, TwistCov = T["geometry_msgs/msg/Twist"], T["geometry_msgs/msg/TwistWithCovariance"]
    zero = Vec(x=0.0, y=0.0, z=0.0)
    ok, bad = (
        Status(status=_STATUS_FIX, service=_SERVICE_GPS),
        Status(status=_STATUS_NO_FIX, service=_SERVICE_GPS),
    )

    def make_fix(v: np.ndarray, i: int, hdr: Any) -> Any:
        cov = np.zeros(9)
        cov[0], cov[4], cov[8] = v[3] ** 2, v[3] ** 2, v[4] ** 2
        return T[_FIX](
            header=hdr,
            status=ok if fix_ok[i] else bad,
            latitude=v[0],
            longitude=v[1],
            altitude=v[2],
            position_covariance=cov,
            position_covariance_type=_COV_DIAGONAL_KNOWN,
        )

    def make_vel(v: np.ndarray, i: int, hdr: Any) -> Any:
        cov = np.zeros(36)
        cov[0] = cov[7] = cov[14] = v[3] ** 2
        lin = Vec(x=v[1], y=v[0], z=-v[2])
        return T[_VEL](
            header=hdr, twist=TwistCov(twist=Twist(linear=lin, angular=zero), covariance=cov)
        )

    stamps = _stamps(gnss.column("t_ns").to_numpy(), opts.time_base)
    fix_values = np.concatenate([pos, acc], axis=1)
    out = [Stream(tp.fix, _FIX, stamps, tp.gnss_frame, fix_values, make_fix, False)]
    if not np.all(np.isnan(vel)):
        vel_values = np.concatenate([vel, s_acc[:, None]], axis=1)
        out.append(Stream(tp.vel, _VEL, stamps, tp.gnss_frame, vel_values, make_vel, False))
    return out


def _merged(
    streams: list[Stream], store: Typestore, ros_version: int
) -> Iterator[tuple[int, int, bytes]]:
    """(stream index, stamp ns, serialized message) of all streams in time order.

    Ties in time go by stream order, then row order.
    """
    serialize = store.serialize_ros1 if ros_version == 1 else store.serialize_cdr
    encode = [encoder(s, store.types, serialize, ros_version) for s in streams]
    t = np.concatenate([s.stamps_ns for s in streams])
    k = np.concatenate([np.full(len(s.stamps_ns), j) for j, s in enumerate(streams)])
    i = np.concatenate([np.arange(len(s.stamps_ns)) for s in streams])
    order = np.lexsort((i, k, t))
    for kk, ii, tt in zip(k[order].tolist(), i[order].tolist(), t[order].tolist(), strict=True):
        yield kk, tt, encode[kk](ii)


def write_mcap(path: str | Path, tables: Mapping[str, pa.Table], opts: RosOptions) -> None:
    """Write the tables as a ROS 2 MCAP file (CDR messages, ``ros2msg`` schemas), atomically."""
    store = typestore(2, tables.get("truth"))
    streams = _streams(tables, store, opts)
    with atomic_path(path) as tmp, tmp.open("wb") as fh:
        writer = McapWriter(fh, compression=CompressionType.ZSTD, chunk_size=1 << 20)
        writer.start(profile="ros2", library=f"navreplay {package_version()}")
        channels = []
        for s in streams:
            schema = writer.register_schema(
                name=s.msgtype,
                encoding="ros2msg",
                data=store.generate_msgdef(s.msgtype, ros_version=2)[0].encode(),
            )
            channels.append(
                writer.register_channel(topic=s.topic, message_encoding="cdr", schema_id=schema)
            )
        seq = [0] * len(streams)
        for k, t, data in _merged(streams, store, 2):
            writer.add_message(channels[k], log_time=t, data=data, publish_time=t, sequence=seq[k])
            seq[k] += 1
        writer.finish()  # type: ignore[no-untyped-call]


def write_bag(path: str | Path, tables: Mapping[str, pa.Table], opts: RosOptions) -> None:
    """Write the tables as a ROS 1 bag (v2.0, LZ4-compressed chunks), atomically."""
    store = typestore(1, tables.get("truth"))
    streams = _streams(tables, store, opts)
    with atomic_path(path) as tmp:
        bag = Bag1Writer(tmp)
        bag.set_compression(Bag1Writer.CompressionFormat.LZ4)
        with bag:
            conns = [bag.add_connection(s.topic, s.msgtype, typestore=store) for s in streams]
            for k, t, data in _merged(streams, store, 1):
                bag.write(conns[k], t, data)
