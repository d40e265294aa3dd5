"""ROS message types -> canonical table columns (shared by the MCAP, ROS 1 and ROS 2 readers).

================================================  =========  ===================================
message type                                      table      columns (source frame)
================================================  =========  ===================================
sensor_msgs/Imu                                   imu        acc_*_mps2 <- linear_acceleration,
                                                             gyro_*_radps <- angular_velocity
                                                             (FLU per REP-103; FRD when the
                                                             frame_id ends in ``_ned``). A
                                                             covariance[0] of -1 marks the
                                                             vector as absent: NaN.
sensor_msgs/NavSatFix                             gnss       lat_deg, lon_deg, alt_m
                                                             (ellipsoidal); fix_type from
                                                             status; h_acc_m = sqrt of the mean
                                                             E/N variance, v_acc_m = sqrt of the
                                                             U variance (null when the
                                                             covariance type is UNKNOWN)
nav_msgs/Odometry, geometry_msgs/TwistStamped,    vehicle    speed_mps <- twist.linear.x,
geometry_msgs/TwistWithCovarianceStamped                     yaw_rate_radps <- twist.angular.z
                                                             (FLU: ``ingest.frames`` negates it)
geometry_msgs/TwistWithCovarianceStamped on a     gnss       vel_{n,e,d}_mps from the ENU linear
GNSS topic (name with gps, gnss, fix, navsat or   (velocity  twist; speed_acc_mps = sqrt of the mean
ublox: a receiver's velocity, e.g. ``/gps/vel``)  companion) linear variance (null when all 0);
                                                             joined to the fixes by time
sensor_msgs/MagneticField                         mag        mag_*_gauss <- magnetic_field (tesla
                                                             x 1e4; FLU, or FRD when the
                                                             frame_id ends in ``_ned``)
any type with float64 lat_deg, lon_deg, alt_m     truth      every top-level float64 field
(e.g. navreplay_msgs/msg/NavTruth)                           under its own name (truth columns
                                                             and sensor biases)
================================================  =========  ===================================

Time: ``header.stamp`` (sensor acquisition time) where the message has a header and the stamp
is set; an int64 ``t_ns`` field for header-less truth messages; otherwise, and for zero
stamps, the log (receive) time, counted in the report.

NavSatStatus -> ``fix_type`` (MAVLink GPS_FIX_TYPE): NO_FIX(-1) -> 1 NO_FIX, FIX(0) -> 3
FIX_3D, SBAS_FIX(1) -> 4 DGPS, GBAS_FIX(2) -> 5 RTK_FLOAT (drivers use GBAS for both RTK float
and fixed, so the weaker of the two is claimed), anything else -> 1 NO_FIX.
"""

from __future__ import annotations

import re
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from navreplay.ingest.arrays import I64
from navreplay.ingest.frames import enu_to_ned
from navreplay.ingest.readers.ros.rosmsg import Decoded, LeafKind, MessageDecoder
from navreplay.ingest.schema import FixType, TableName, spec

Columns = dict[str, np.ndarray]
Nulls = dict[str, npt.NDArray[np.bool_]]

_STAMP = ("header.stamp.sec", "header.stamp.nanosec")
_TWIST_COV = "geometry_msgs/msg/TwistWithCovarianceStamped"
_VEC = ("x", "y", "z")
_TRUTH_REQUIRED = ("lat_deg", "lon_deg", "alt_m")


@dataclass(frozen=True)
class Converted:
    """Columns of one batch, their null masks, counters for the report and string samples."""

    columns: Columns
    nulls: Nulls
    counters: dict[str, int]
    info: dict[str, str]


@dataclass(frozen=True)
class RosConversion:
    """How one message type becomes rows of a canonical table.

    Attributes:
        table: the table fed.
        frame: axis convention of the vector columns produced (``flu``, ``frd`` or None).
        wants: leaves the decoder must return.
        convert: (decoded leaves, log times) -> Converted.
        optional: leaves among ``wants`` the conversion does without.
        role: ``""`` for a table's primary stream; ``velocity`` for a GNSS velocity stream
            whose columns are joined to the fixes.
    """

    table: TableName
    frame: str | None
    wants: tuple[str, ...]
    convert: Callable[[Decoded, I64], Converted]
    optional: tuple[str, ...] = ("header.frame_id",)
    role: str = ""


GNSS_TOPIC = re.compile(r"gps|gnss|fix|navsat|ublox", re.IGNORECASE)


def conversion_for(
    decoder: MessageDecoder, topic: str = ""
) -> tuple[RosConversion | None, str | None]:
    """The conversion of ``decoder``'s message type on ``topic`` (None if it feeds no table),
    and why a known type cannot be converted (its definition lacks a field it needs)."""
    if decoder.msgtype == _TWIST_COV and GNSS_TOPIC.search(topic):
        conv: RosConversion | None = _gnss_velocity(decoder)
    else:
        conv = _conversion(decoder)
    if conv is None:
        return None, None
    missing = [p for p in conv.wants if p not in conv.optional and decoder.leaf(p) is None]
    if missing:
        return None, f"its definition lacks {', '.join(missing)}"
    return conv, None


_TWISTS = {
    "nav_msgs/msg/Odometry": "twist.twist",
    _TWIST_COV: "twist.twist",
    "geometry_msgs/msg/TwistStamped": "twist",
}


def _conversion(decoder: MessageDecoder) -> RosConversion | None:
    name = decoder.msgtype
    if name == "sensor_msgs/msg/Imu":
        return _imu(decoder)
    if name == "sensor_msgs/msg/NavSatFix":
        return _navsatfix(decoder)
    if name == "sensor_msgs/msg/MagneticField":
        return _magnetic_field(decoder)
    if name in _TWISTS:
        return _twist(decoder, _TWISTS[name])
    return _truth_like(decoder)


def _time(decoder: MessageDecoder) -> tuple[str, ...]:
    if all(decoder.leaf(p) is not None for p in _STAMP):
        return _STAMP
    t = decoder.leaf("t_ns")
    if t is not None and t.kind == LeafKind.PRIM and t.dtype in ("i8", "u8") and t.count == 1:
        return ("t_ns",)
    return ()


def _t_ns(decoded: Decoded, time_leaves: tuple[str, ...], log_ns: I64) -> tuple[I64, int]:
    """Row times and the number of rows that fell back to the log time."""
    if time_leaves == _STAMP:
        sec = decoded.values[_STAMP[0]].astype(np.int64)
        nsec = decoded.values[_STAMP[1]].astype(np.int64)
        t = sec * 1_000_000_000 + nsec
        unset = (sec == 0) & (nsec == 0)
        if unset.any():
            t = np.where(unset, log_ns, t)
        return t, int(unset.sum())
    if time_leaves == ("t_ns",):
        return decoded.values["t_ns"].astype(np.int64), 0
    return log_ns.astype(np.int64, copy=True), len(log_ns)


def _imu(decoder: MessageDecoder) -> RosConversion:
    tl = _time(decoder)
    vec = tuple(f"{g}.{a}" for g in ("angular_velocity", "linear_acceleration") for a in _VEC)
    covs = ("angular_velocity_covariance", "linear_acceleration_covariance")
    wants = (*tl, *vec, *covs, "header.frame_id")
    optional = (*covs, "header.frame_id")

    def convert(d: Decoded, log_ns: I64) -> Converted:
        t, fallback = _t_ns(d, tl, log_ns)
        cols: Columns = {"t_ns": t}
        counters = {"time_from_log": fallback}
        for group, prefix, unit in (
            ("angular_velocity", "gyro", "radps"),
            ("linear_acceleration", "acc", "mps2"),
        ):
            cov = d.values.get(f"{group}_covariance")
            absent = cov[:, 0] == -1.0 if cov is not None else np.zeros(len(t), bool)
            for a in _VEC:
                v = d.values[f"{group}.{a}"].astype(np.float64)
                cols[f"{prefix}_{a}_{unit}"] = np.where(absent, np.nan, v) if absent.any() else v
            counters[f"{prefix}_marked_absent"] = int(absent.sum())
        return Converted(cols, {}, counters, {"frame_id": d.strings.get("header.frame_id", "")})

    return RosConversion(TableName.IMU, "flu", wants, convert, optional)


#: gauss per tesla
GAUSS_PER_TESLA = 1.0e4


def _magnetic_field(decoder: MessageDecoder) -> RosConversion:
    tl = _time(decoder)
    wants = (*tl, *(f"magnetic_field.{a}" for a in _VEC), "header.frame_id")

    def convert(d: Decoded, log_ns: I64) -> Converted:
        t, fallback = _t_ns(d, tl, log_ns)
        cols: Columns = {"t_ns": t}
        for a in _VEC:
            cols[f"mag_{a}_gauss"] = d.values[f"magnetic_field.{a}"].astype(np.float64) * (
                GAUSS_PER_TESLA
            )
        info = {"frame_id": d.strings.get("header.frame_id", ""), "units": "tesla -> gauss"}
        return Converted(cols, {}, {"time_from_log": fallback}, info)

    return RosConversion(TableName.MAG, "flu", wants, convert)


_STATUS_TO_FIX = {-1: FixType.NO_FIX, 0: FixType.FIX_3D, 1: FixType.DGPS, 2: FixType.RTK_FLOAT}


def _navsatfix(decoder: MessageDecoder) -> RosConversion:
    tl = _time(decoder)
    wants = (
        *tl,
        "latitude",
        "longitude",
        "altitude",
        "status.status",
        "position_covariance",
        "position_covariance_type",
        "header.frame_id",
    )

    def convert(d: Decoded, log_ns: I64) -> Converted:
        t, fallback = _t_ns(d, tl, log_ns)
        status = d.values["status.status"].astype(np.int64)
        fix = np.full(len(t), FixType.NO_FIX, dtype=np.int8)
        for code, ft in _STATUS_TO_FIX.items():
            fix[status == code] = ft
        cov = d.values["position_covariance"].astype(np.float64)
        unknown = d.values["position_covariance_type"] == 0
        with np.errstate(invalid="ignore"):
            h_acc = np.sqrt(0.5 * (cov[:, 0] + cov[:, 4]))
            v_acc = np.sqrt(cov[:, 8])
        cols: Columns = {
            "t_ns": t,
            "lat_deg": d.values["latitude"].astype(np.float64),
            "lon_deg": d.values["longitude"].astype(np.float64),
            "alt_m": d.values["altitude"].astype(np.float64),
            "h_acc_m": h_acc,
            "v_acc_m": v_acc,
            "fix_type": fix,
        }
        counters = {
            "time_from_log": fallback,
            "no_fix": int((fix == FixType.NO_FIX).sum()),
            "covariance_unknown": int(unknown.sum()),
        }
        nulls: Nulls = {"h_acc_m": unknown, "v_acc_m": unknown} if unknown.any() else {}
        return Converted(cols, nulls, counters, {"frame_id": d.strings.get("header.frame_id", "")})

    return RosConversion(TableName.GNSS, None, wants, convert)


def _twist(decoder: MessageDecoder, base: str) -> RosConversion | None:
    tl = _time(decoder)
    speed, yaw = f"{base}.linear.x", f"{base}.angular.z"
    if decoder.leaf(speed) is None or decoder.leaf(yaw) is None or not tl:
        return None
    wants = (*tl, speed, yaw, "header.frame_id")

    def convert(d: Decoded, log_ns: I64) -> Converted:
        t, fallback = _t_ns(d, tl, log_ns)
        cols: Columns = {
            "t_ns": t,
            "speed_mps": d.values[speed].astype(np.float64),
            "yaw_rate_radps": d.values[yaw].astype(np.float64),
        }
        return Converted(
            cols,
            {},
            {"time_from_log": fallback},
            {"frame_id": d.strings.get("header.frame_id", "")},
        )

    return RosConversion(TableName.VEHICLE, "flu", wants, convert)


def _gnss_velocity(decoder: MessageDecoder) -> RosConversion | None:
    tl = _time(decoder)
    lin = tuple(f"twist.twist.linear.{a}" for a in _VEC)
    wants = (*tl, *lin, "twist.covariance", "header.frame_id")

    def convert(d: Decoded, log_ns: I64) -> Converted:
        t, fallback = _t_ns(d, tl, log_ns)
        e, n, u = (d.values[p].astype(np.float64) for p in lin)
        vn, ve, vd = enu_to_ned(e, n, u)
        cov = d.values["twist.covariance"].astype(np.float64)
        unknown = (cov[:, [0, 7, 14]] == 0.0).all(axis=1)
        with np.errstate(invalid="ignore"):
            s_acc = np.sqrt(cov[:, [0, 7, 14]].mean(axis=1))
        cols: Columns = {
            "t_ns": t,
            "vel_n_mps": vn,
            "vel_e_mps": ve,
            "vel_d_mps": vd,
            "speed_acc_mps": s_acc,
        }
        nulls: Nulls = {"speed_acc_mps": unknown} if unknown.any() else {}
        info = {"frame_id": d.strings.get("header.frame_id", ""), "velocity": "ENU -> NED"}
        return Converted(cols, nulls, {"time_from_log": fallback}, info)

    return RosConversion(TableName.GNSS, None, wants, convert, role="velocity")


def truth_fields(decoder: MessageDecoder) -> list[str]:
    """Top-level float64 scalar fields of a truth-like message (empty if it is not one)."""
    names = [
        leaf.path
        for leaf in decoder.leaves
        if leaf.kind == LeafKind.PRIM
        and leaf.dtype == "f8"
        and leaf.count == 1
        and "." not in leaf.path
        and "[" not in leaf.path
    ]
    return names if all(r in names for r in _TRUTH_REQUIRED) else []


def _truth_like(decoder: MessageDecoder) -> RosConversion | None:
    fields = truth_fields(decoder)
    if not fields:
        return None
    tl = _time(decoder)
    known = {c.name for c in spec(TableName.TRUTH).columns}
    wants = (*tl, *fields)

    def convert(d: Decoded, log_ns: I64) -> Converted:
        t, fallback = _t_ns(d, tl, log_ns)
        cols: Columns = {"t_ns": t}
        for f in fields:
            cols[f] = d.values[f].astype(np.float64)
        extra = sorted(set(fields) - known)
        info = {"extra_columns": ",".join(extra)} if extra else {}
        return Converted(cols, {}, {"time_from_log": fallback}, info)

    return RosConversion(TableName.TRUTH, None, wants, convert)
