"""PX4 ULog topics that feed canonical tables, and their conversion to canonical columns.

pyulog gives each topic as a dict of column arrays (array fields flattened to ``name[i]``);
the converters below only rename, scale and combine them (see ``ingest.readers.ulog.ulog`` for the
topic table). Field names changed across PX4 releases (``vehicle_gps_position`` became
``sensor_gps``, integer ``lat``/``lon`` became ``latitude_deg``/``longitude_deg``): both are
read.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass

import numpy as np

from navreplay.ingest.arrays import F64
from navreplay.ingest.readers.mavlink.mavmsgs import Converted
from navreplay.ingest.schema import FixType, TableName

Data = Mapping[str, np.ndarray]
#: PX4's CONSTANTS_RADIUS_OF_EARTH (geo.h), the sphere of its map projection.
PX4_EARTH_RADIUS_M = 6_371_000.0
GPS_TOPICS = ("vehicle_gps_position", "sensor_gps")


@dataclass(frozen=True)
class UlogTopic:
    """A ULog topic that feeds a canonical table.

    Attributes:
        name: topic name.
        table: canonical table.
        convert: topic columns and the log's geoid undulation (m or None) -> columns.
        attitude: the attitude topic joined by time (roll, pitch, yaw), or "" for none.
        pair: a topic of the same instance whose converted columns are joined by time
            (``sensor_gyro`` onto ``sensor_accel``), or "" for none.
        fallback_for: offered only when the log has no such topic (``sensor_accel`` when
            there is no ``sensor_combined``: selections of existing logs stay as they were).
        detail: what ``--list`` shows.
    """

    name: str
    table: TableName
    convert: Callable[[Data, float | None], Converted]
    attitude: str = ""
    detail: str = ""
    pair: str = ""
    fallback_for: str = ""


def _f(data: Data, name: str, per: float = 1.0) -> F64:
    values = np.asarray(data[name], dtype=np.float64)
    return values / per if per != 1.0 else values


def _imu(data: Data, _und: float | None) -> Converted:
    cols = {f"acc_{a}_mps2": _f(data, f"accelerometer_m_s2[{i}]") for i, a in enumerate("xyz")}
    cols |= {f"gyro_{a}_radps": _f(data, f"gyro_rad[{i}]") for i, a in enumerate("xyz")}
    info = {"time": "timestamp (the gyro sample; accelerometer_timestamp_relative not applied)"}
    return Converted(cols, info=info)


def _accel(data: Data, _und: float | None) -> Converted:
    cols = {f"acc_{a}_mps2": _f(data, a) for a in "xyz"}
    return Converted(cols, info={"time": "sensor_accel timestamp; sensor_gyro nearest in time"})


def _magnetometer(data: Data, _und: float | None) -> Converted:
    cols = {f"mag_{a}_gauss": _f(data, f"magnetometer_ga[{i}]") for i, a in enumerate("xyz")}
    return Converted(cols, info={"units": "gauss (vehicle_magnetometer: calibrated, body frame)"})


def _sensor_mag(data: Data, _und: float | None) -> Converted:
    cols = {f"mag_{a}_gauss": _f(data, a) for a in "xyz"}
    return Converted(cols, info={"units": "gauss (sensor_mag: the driver's, board frame)"})


def gyro_columns(data: Data) -> dict[str, np.ndarray]:
    """``sensor_gyro`` ``x/y/z`` rad/s as the IMU's gyro columns."""
    return {f"gyro_{a}_radps": _f(data, a) for a in "xyz"}


def _gps(data: Data, und: float | None) -> Converted:
    if "latitude_deg" in data:  # PX4 >= 1.14 sensor_gps
        lat, lon = _f(data, "latitude_deg"), _f(data, "longitude_deg")
        msl, ell = _f(data, "altitude_msl_m"), _f(data, "altitude_ellipsoid_m")
    else:
        lat, lon = _f(data, "lat", 1e7), _f(data, "lon", 1e7)
        msl = _f(data, "alt", 1e3)
        ell = _f(data, "alt_ellipsoid", 1e3) if "alt_ellipsoid" in data else np.zeros(len(lat))
    has_ell = ell != 0.0
    alt = np.where(has_ell, ell, msl + (und or 0.0))
    valid_vel = (
        np.asarray(data["vel_ned_valid"], bool)
        if "vel_ned_valid" in data
        else np.ones(len(lat), bool)
    )
    vel = np.stack([_f(data, f"vel_{a}_m_s") for a in "ned"])
    never_set = not valid_vel.any() and bool(np.any(vel != 0.0))
    if never_set:
        # PX4 SITL's simulated receiver (1.9) never sets the flag while its velocities match
        # the simulator's to 0.1 m/s: a flag nobody maintains, not invalid velocities.
        valid_vel = np.ones(len(lat), bool)
    fix = np.asarray(data["fix_type"], dtype=np.int8)
    cols = {
        "lat_deg": lat,
        "lon_deg": lon,
        "alt_m": alt,
        **{f"vel_{a}_mps": np.where(valid_vel, _f(data, f"vel_{a}_m_s"), 0.0) for a in "ned"},
        "h_acc_m": _f(data, "eph"),
        "v_acc_m": _f(data, "epv"),
        "speed_acc_mps": _f(data, "s_variance_m_s"),
        "fix_type": fix,
        "num_sats": np.asarray(data["satellites_used"], dtype=np.int16),
        **{dop: _f(data, dop) for dop in ("hdop", "vdop") if dop in data},
    }
    nulls = {f"vel_{a}_mps": ~valid_vel for a in "ned"}
    counters = {"no_fix": int((fix < FixType.FIX_2D).sum())}
    if never_set:
        counters["vel_ned_valid_never_set_velocity_used"] = len(lat)
    if (~has_ell).any():
        counters["alt_msl_no_geoid" if und is None else "alt_msl_plus_undulation"] = int(
            (~has_ell).sum()
        )
    return Converted(cols, nulls, counters, {"accuracy": "eph/epv (m), s_variance_m_s (m/s)"})


def _global_position(data: Data, und: float | None) -> Converted:
    n = len(data["timestamp"])
    # alt_ellipsoid of 0 is "not given" (PX4 SITL logs 0 there): MSL plus the log's undulation.
    ell = _f(data, "alt_ellipsoid") if "alt_ellipsoid" in data else np.zeros(n)
    has_ell = ell != 0.0
    alt = np.where(has_ell, ell, _f(data, "alt") + (und or 0.0))
    cols = {"lat_deg": _f(data, "lat"), "lon_deg": _f(data, "lon"), "alt_m": alt}
    nulls = {}
    for a in "ned":
        if f"vel_{a}" in data:
            cols[f"vel_{a}_mps"] = _f(data, f"vel_{a}")
        else:
            cols[f"vel_{a}_mps"] = np.zeros(n)
            nulls[f"vel_{a}_mps"] = np.ones(n, bool)
    msl = int((~has_ell).sum())
    counters = {} if not msl or und is not None else {"alt_msl_no_geoid": msl}
    return Converted(cols, nulls, counters)


def reproject(x_m: F64, y_m: F64, ref_lat_deg: F64, ref_lon_deg: F64) -> tuple[F64, F64]:
    """PX4's azimuthal equidistant ``map_projection_reproject``: local NED -> lat/lon deg."""
    lat0, lon0 = np.radians(ref_lat_deg), np.radians(ref_lon_deg)
    xr, yr = x_m / PX4_EARTH_RADIUS_M, y_m / PX4_EARTH_RADIUS_M
    c = np.hypot(xr, yr)
    sin_c, cos_c = np.sin(c), np.cos(c)
    safe = np.where(c > 0, c, 1.0)
    lat = np.where(c > 0, np.arcsin(cos_c * np.sin(lat0) + xr * sin_c * np.cos(lat0) / safe), lat0)
    lon = np.where(
        c > 0,
        lon0 + np.arctan2(yr * sin_c, c * np.cos(lat0) * cos_c - xr * np.sin(lat0) * sin_c),
        lon0,
    )
    return np.degrees(lat), np.degrees(lon)


def _local_position(data: Data, und: float | None) -> Converted:
    xy = np.asarray(data["xy_global"], bool)
    z = np.asarray(data["z_global"], bool)
    lat, lon = reproject(_f(data, "x"), _f(data, "y"), _f(data, "ref_lat"), _f(data, "ref_lon"))
    alt = _f(data, "ref_alt") - _f(data, "z") + (und or 0.0)
    cols = {
        "lat_deg": np.where(xy, lat, np.nan),
        "lon_deg": np.where(xy, lon, np.nan),
        "alt_m": np.where(z, alt, np.nan),
        "vel_n_mps": _f(data, "vx"),
        "vel_e_mps": _f(data, "vy"),
        "vel_d_mps": _f(data, "vz"),
    }
    counters = {"position_not_global": int((~xy).sum())}
    return Converted(cols, counters=counters, info={"position": "ref_lat/lon/alt + x/y/z"})


def euler_from_quaternion(q: F64) -> tuple[F64, F64, F64]:
    """ZYX roll, pitch, yaw (rad) of Hamilton quaternions ``q`` (n, 4) [w, x, y, z]."""
    w, x, y, z = q.T
    roll = np.arctan2(2 * (w * x + y * z), 1 - 2 * (x * x + y * y))
    pitch = np.arcsin(np.clip(2 * (w * y - z * x), -1.0, 1.0))
    yaw = np.arctan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))
    return roll, pitch, yaw


def attitude_columns(data: Data) -> dict[str, np.ndarray]:
    """roll/pitch/yaw (rad) of ``vehicle_attitude`` (``q``: body FRD -> NED)."""
    q = np.stack([_f(data, f"q[{i}]") for i in range(4)], axis=1)
    q /= np.linalg.norm(q, axis=1, keepdims=True)
    roll, pitch, yaw = euler_from_quaternion(q)
    return {"roll_rad": roll, "pitch_rad": pitch, "yaw_rad": yaw}


TOPICS: tuple[UlogTopic, ...] = (
    UlogTopic("sensor_combined", TableName.IMU, _imu, detail="rad/s, m/s^2"),
    UlogTopic(
        "sensor_accel",
        TableName.IMU,
        _accel,
        detail="m/s^2 + sensor_gyro rad/s (board frame since PX4 1.11)",
        pair="sensor_gyro",
        fallback_for="sensor_combined",
    ),
    UlogTopic("vehicle_gps_position", TableName.GNSS, _gps, detail="1e-7 deg, mm"),
    UlogTopic("sensor_gps", TableName.GNSS, _gps, detail="receiver fixes"),
    UlogTopic(
        "vehicle_global_position",
        TableName.ESTIMATOR,
        _global_position,
        attitude="vehicle_attitude",
        detail="EKF global position + vehicle_attitude",
    ),
    UlogTopic(
        "vehicle_local_position",
        TableName.ESTIMATOR,
        _local_position,
        attitude="vehicle_attitude",
        detail="EKF local position + vehicle_attitude",
    ),
    UlogTopic(
        "vehicle_global_position_groundtruth",
        TableName.TRUTH,
        _global_position,
        attitude="vehicle_attitude_groundtruth",
        detail="simulator truth (SITL) + vehicle_attitude_groundtruth",
    ),
    UlogTopic("vehicle_magnetometer", TableName.MAG, _magnetometer, detail="gauss, calibrated"),
    UlogTopic(
        "sensor_mag",
        TableName.MAG,
        _sensor_mag,
        detail="gauss, the driver's (board frame since PX4 1.11)",
        fallback_for="vehicle_magnetometer",
    ),
)
