"""MAVLink messages that feed canonical tables, and their conversion to canonical columns.

Each ``MavStream`` says which table a message fills, where its time and sensor instance come
from, and converts a block of decoded payloads (a numpy structured array in the dialect's
wire layout) into canonical columns. Scalings are those of the MAVLink definitions:

==================  ========================================================================
RAW_IMU             ``x/y/zacc`` mG (ArduPilot sends RAW_IMU identical to SCALED_IMU),
SCALED_IMU[2|3]     ``x/y/zgyro`` mrad/s, body FRD; instance ``id`` (RAW_IMU) or the name's
                    number (SCALED_IMU2 is the second IMU: instance 1)
HIGHRES_IMU         m/s^2 and rad/s (float32), body FRD; instance ``id``
GPS_RAW_INT,        ``lat/lon`` 1e-7 deg; ``alt`` mm above MSL, ``alt_ellipsoid`` mm (MAVLink 2
GPS2_RAW            extension; 0 when absent); ``vel`` cm/s ground speed and ``cog`` cdeg
                    (UINT16_MAX unknown); ``h_acc``/``v_acc`` mm, ``vel_acc`` mm/s (0 unknown),
                    else ``eph``/``epv`` (DOP x 100, UINT16_MAX unknown) taken as metres;
                    ``satellites_visible`` (UINT8_MAX unknown) -> num_sats; ``eph``/``epv``
                    / 100 -> ``hdop``/``vdop`` too
GLOBAL_POSITION_INT ``lat/lon`` 1e-7 deg, ``alt`` mm MSL, ``vx/vy/vz`` cm/s NED; joined with
 + ATTITUDE         ATTITUDE ``roll/pitch/yaw`` (rad) and EKF_STATUS_REPORT (the square
 + EKF_STATUS_...   roots of the EKF's test ratios) by time -> ``estimator``
SIMSTATE            ArduPilot SITL truth: attitude (rad), ``lat/lng`` 1e-7 deg; no altitude
                    or velocity (alt NaN, velocity null)
SIM_STATE           common-set simulator truth: attitude, ``lat_int/lon_int`` 1e-7 deg (else
                    the float ``lat/lon`` deg), ``alt`` m, ``vn/ve/vd`` m/s
RAW_IMU.mag,        the magnetometer fields of the IMU messages -> ``mag`` (streams of their
SCALED_IMU[2|3].mag own, named with the ``.mag`` suffix): ``x/y/zmag`` mgauss (ArduPilot's
HIGHRES_IMU.mag     RAW_IMU too), gauss in HIGHRES_IMU; body FRD; a stream exists only where
                    some message carries a field (not all three 0: no compass), and rows of
                    0, 0, 0 are NaN (``mag_not_reported``)
==================  ========================================================================

Heights: the canonical ``alt_m`` is ellipsoidal. ``alt_ellipsoid`` is used where the packet
has it; an MSL height gets the geoid undulation the same log reports (the median of
``alt_ellipsoid - alt`` over its GPS packets) or, without one, stays MSL and is counted
(``alt_msl_no_geoid``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np
import numpy.typing as npt

from navreplay.ingest.schema import ESTIMATOR_TEST_RATIOS, FixType, TableName

G0 = 9.80665
UINT8_MAX = 255
UINT16_MAX = 65535

Columns = dict[str, np.ndarray]
Nulls = dict[str, npt.NDArray[np.bool_]]
Rec = np.ndarray[Any, Any]


@dataclass
class Converted:
    """Canonical columns of a block of messages (``t_ns`` is added by the reader)."""

    columns: Columns
    nulls: Nulls = field(default_factory=dict)
    counters: dict[str, int] = field(default_factory=dict)
    info: dict[str, str] = field(default_factory=dict)


@dataclass(frozen=True)
class Extras:
    """Per-file facts a conversion needs: the geoid undulation N (ellipsoid = MSL + N), m."""

    undulation_m: float | None = None


class MavJoin(NamedTuple):
    """A message joined to a stream's rows by nearest time: its name, time field (None: the
    tlog stamp on the vehicle clock), conversion and the columns it adds."""

    message: str
    time_field: str | None
    convert: Callable[[Rec, Extras], Converted]
    columns: tuple[str, ...]


@dataclass(frozen=True)
class MavStream:
    """A message that feeds a canonical table.

    Attributes:
        message: MAVLink message name.
        table: canonical table.
        time_field: ``time_boot_ms``, ``time_usec`` (epoch or boot, by magnitude) or None
            (the message has no time: the tlog stamp is mapped onto the vehicle clock).
        convert: structured payloads -> canonical columns.
        instance_field: field holding the sensor instance, if any.
        instance: the instance when the message name implies it.
        joins: messages joined to each row by nearest time, in turn, each with its time field
            and conversion.
        detail: what ``--list`` shows.
        suffix: appended to the message name to name the stream when the message feeds a
            second table (``RAW_IMU.mag``).
        carries: the fields of which one must be non-zero for a message to carry the
            stream's data (a compass), or () for every message.
    """

    message: str
    table: TableName
    time_field: str | None
    convert: Callable[[Rec, Extras], Converted]
    instance_field: str | None = None
    instance: int = 0
    joins: tuple[MavJoin, ...] = ()
    detail: str = ""
    suffix: str = ""
    carries: tuple[str, ...] = ()

    @property
    def name(self) -> str:
        """The stream's name: the message's, with the suffix."""
        return self.message + self.suffix

    def key(self, instance: int) -> str:
        """Stream key: the name, with ``[n]`` for an instance n > 0 read from a field."""
        if self.instance_field is None or instance == 0:
            return self.name
        return f"{self.name}[{instance}]"

    def present(self, rec: Rec) -> npt.NDArray[np.bool_]:
        """Which decoded messages carry the stream's data."""
        names = rec.dtype.names or ()
        if not self.carries:
            return np.ones(len(rec), bool)
        if not all(f in names for f in self.carries):
            return np.zeros(len(rec), bool)
        carried: npt.NDArray[np.bool_] = np.logical_or.reduce(
            [np.asarray(rec[f]) != 0 for f in self.carries]
        )
        return carried


def _f64(rec: Rec, name: str, per: float = 1.0) -> npt.NDArray[np.float64]:
    """Field ``name`` as float64 divided by ``per`` (a decimal unit: 1e7 for 1e-7 deg)."""
    values = np.asarray(rec[name], dtype=np.float64)
    return values / per if per != 1.0 else values


def _imu_scaled(rec: Rec, _ex: Extras) -> Converted:
    cols = {f"acc_{a}_mps2": _f64(rec, f"{a}acc", 1e3) * G0 for a in "xyz"}
    cols |= {f"gyro_{a}_radps": _f64(rec, f"{a}gyro", 1e3) for a in "xyz"}
    return Converted(cols, info={"units": "mG and mrad/s scaled to m/s^2 and rad/s"})


def _imu_highres(rec: Rec, _ex: Extras) -> Converted:
    cols = {f"acc_{a}_mps2": _f64(rec, f"{a}acc") for a in "xyz"}
    cols |= {f"gyro_{a}_radps": _f64(rec, f"{a}gyro") for a in "xyz"}
    upd = np.asarray(rec["fields_updated"], dtype=np.int64)
    partial = int(((upd & 0x3F) != 0x3F).sum())
    return Converted(cols, counters={"highres_imu_not_all_updated": partial} if partial else {})


_MAG_FIELDS = ("xmag", "ymag", "zmag")


def _mag(rec: Rec, per: float, units: str) -> Converted:
    """``x/y/zmag`` in units of 1/``per`` gauss; messages of 0, 0, 0 (no compass) -> NaN."""
    cols = {f"mag_{a}_gauss": _f64(rec, f"{a}mag", per) for a in "xyz"}
    missing = np.logical_and.reduce([np.asarray(rec[f]) == 0 for f in _MAG_FIELDS])
    counters: dict[str, int] = {}
    if missing.any():
        counters["mag_not_reported"] = int(missing.sum())
        cols = {k: np.where(missing, np.nan, v) for k, v in cols.items()}
    return Converted(cols, counters=counters, info={"units": units})


def _mag_scaled(rec: Rec, _ex: Extras) -> Converted:
    return _mag(rec, 1e3, "mgauss scaled to gauss")


def _mag_highres(rec: Rec, _ex: Extras) -> Converted:
    out = _mag(rec, 1.0, "gauss")
    upd = np.asarray(rec["fields_updated"], dtype=np.int64)
    stale = int(((upd & 0x1C0) != 0x1C0).sum())
    if stale:
        out.counters["highres_mag_not_updated"] = stale
    return out


def _height(
    alt_msl_m: npt.NDArray[np.float64],
    alt_ell_m: npt.NDArray[np.float64] | None,
    ex: Extras,
) -> tuple[npt.NDArray[np.float64], dict[str, int]]:
    """Ellipsoidal height from the packet, else MSL + the log's undulation, else MSL."""
    msl = alt_msl_m + (ex.undulation_m or 0.0)
    if alt_ell_m is None:
        has_ell = np.zeros(len(alt_msl_m), bool)
        out = msl
    else:
        has_ell = alt_ell_m != 0.0
        out = np.where(has_ell, alt_ell_m, msl)
    counters: dict[str, int] = {}
    missing = int((~has_ell).sum())
    if missing:
        key = "alt_msl_plus_undulation" if ex.undulation_m is not None else "alt_msl_no_geoid"
        counters[key] = missing
    return np.asarray(out, dtype=np.float64), counters


def _accuracy(
    rec: Rec, acc_field: str, dop_field: str, per: float
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.bool_], int]:
    """(value m, null mask, rows taken from the DOP field) of an accuracy."""
    names = rec.dtype.names or ()
    acc = _f64(rec, acc_field, 1e3) if acc_field in names else np.zeros(len(rec))
    dop = np.asarray(rec[dop_field], dtype=np.int64)
    from_dop = (acc <= 0) & (dop != UINT16_MAX)
    unknown = (acc <= 0) & ~from_dop
    value = np.where(acc > 0, acc, np.where(unknown, 0.0, dop / per))
    return value, unknown, int(from_dop.sum())


def _gps(rec: Rec, ex: Extras) -> Converted:
    names = rec.dtype.names or ()
    alt_ell = _f64(rec, "alt_ellipsoid", 1e3) if "alt_ellipsoid" in names else None
    alt, counters = _height(_f64(rec, "alt", 1e3), alt_ell, ex)
    vel = np.asarray(rec["vel"], dtype=np.int64)
    cog = np.asarray(rec["cog"], dtype=np.int64)
    known = (vel != UINT16_MAX) & ((cog != UINT16_MAX) | (vel == 0))
    speed = np.where(known, vel, 0) / 100.0
    course = np.radians(np.where(cog == UINT16_MAX, 0, cog) / 100.0)
    h_acc, h_null, h_dop = _accuracy(rec, "h_acc", "eph", 100.0)
    v_acc, v_null, _ = _accuracy(rec, "v_acc", "epv", 100.0)
    s_acc = _f64(rec, "vel_acc", 1e3) if "vel_acc" in names else np.zeros(len(rec))
    s_acc = np.maximum(s_acc, 0.0)
    sats = np.asarray(rec["satellites_visible"], dtype=np.int16)
    fix = np.asarray(rec["fix_type"], dtype=np.int8)
    cols: Columns = {
        "lat_deg": _f64(rec, "lat", 1e7),
        "lon_deg": _f64(rec, "lon", 1e7),
        "alt_m": alt,
        "vel_n_mps": speed * np.cos(course),
        "vel_e_mps": speed * np.sin(course),
        "h_acc_m": h_acc,
        "v_acc_m": v_acc,
        "speed_acc_mps": s_acc,
        "fix_type": fix,
        "num_sats": sats,
        "hdop": _f64(rec, "eph", 100.0),
        "vdop": _f64(rec, "epv", 100.0),
    }
    nulls: Nulls = {
        "vel_n_mps": ~known,
        "vel_e_mps": ~known,
        "h_acc_m": h_null,
        "v_acc_m": v_null,
        "hdop": np.asarray(rec["eph"]) == UINT16_MAX,
        "vdop": np.asarray(rec["epv"]) == UINT16_MAX,
        "speed_acc_mps": s_acc <= 0,
        "num_sats": sats == UINT8_MAX,
    }
    counters["no_fix"] = int((fix < FixType.FIX_2D).sum())
    if h_dop:
        counters["h_acc_from_eph"] = h_dop
    info = {"velocity": "ground speed and course (cm/s, cdeg) -> north/east; no vertical"}
    return Converted(cols, nulls, counters, info)


def _global_position(rec: Rec, ex: Extras) -> Converted:
    alt, counters = _height(_f64(rec, "alt", 1e3), None, ex)
    cols: Columns = {
        "lat_deg": _f64(rec, "lat", 1e7),
        "lon_deg": _f64(rec, "lon", 1e7),
        "alt_m": alt,
        "vel_n_mps": _f64(rec, "vx", 100.0),
        "vel_e_mps": _f64(rec, "vy", 100.0),
        "vel_d_mps": _f64(rec, "vz", 100.0),
    }
    return Converted(cols, counters=counters)


def _attitude(rec: Rec, _ex: Extras) -> Converted:
    return Converted({f"{a}_rad": _f64(rec, a) for a in ("roll", "pitch", "yaw")})


_ATTITUDE = ("roll_rad", "pitch_rad", "yaw_rad")


def _ekf_status(rec: Rec, _ex: Extras) -> Converted:
    """EKF_STATUS_REPORT: ArduPilot sends the square roots of its EKF's innovation test ratios
    in the ``*_variance`` fields (``getVariances``; compass: the length of the three axes'
    vector), as XKF4 logs them; a report with ``flags`` 0 (no EKF solution yet) is NaN."""
    running = rec["flags"] != 0
    fields = ("velocity_variance", "pos_horiz_variance", "pos_vert_variance", "compass_variance")
    return Converted({
        name: np.where(running, _f64(rec, f), np.nan)
        for name, f in zip(ESTIMATOR_TEST_RATIOS, fields, strict=True)
    })  # fmt: skip


def _simstate(rec: Rec, _ex: Extras) -> Converted:
    n = len(rec)
    cols: Columns = {
        "lat_deg": _f64(rec, "lat", 1e7),
        "lon_deg": _f64(rec, "lng", 1e7),
        "alt_m": np.full(n, np.nan),
        **{f"{a}_rad": _f64(rec, a) for a in ("roll", "pitch", "yaw")},
    }
    return Converted(cols, info={"missing": "SIMSTATE has no altitude (NaN) or velocity (null)"})


def _sim_state(rec: Rec, _ex: Extras) -> Converted:
    lat_i, lon_i = _f64(rec, "lat_int"), _f64(rec, "lon_int")
    ints = (lat_i != 0) | (lon_i != 0)
    cols: Columns = {
        "lat_deg": np.where(ints, lat_i / 1e7, _f64(rec, "lat")),
        "lon_deg": np.where(ints, lon_i / 1e7, _f64(rec, "lon")),
        "alt_m": _f64(rec, "alt"),
        "vel_n_mps": _f64(rec, "vn"),
        "vel_e_mps": _f64(rec, "ve"),
        "vel_d_mps": _f64(rec, "vd"),
        **{f"{a}_rad": _f64(rec, a) for a in ("roll", "pitch", "yaw")},
    }
    float_rows = int((~ints).sum())
    return Converted(cols, counters={"latlon_from_float_deg": float_rows} if float_rows else {})


_IMU = TableName.IMU
_GNSS = TableName.GNSS

STREAMS: tuple[MavStream, ...] = (
    MavStream("RAW_IMU", _IMU, "time_usec", _imu_scaled, "id", detail="mG, mrad/s"),
    MavStream("SCALED_IMU", _IMU, "time_boot_ms", _imu_scaled, detail="mG, mrad/s"),
    MavStream("SCALED_IMU2", _IMU, "time_boot_ms", _imu_scaled, instance=1, detail="mG, mrad/s"),
    MavStream("SCALED_IMU3", _IMU, "time_boot_ms", _imu_scaled, instance=2, detail="mG, mrad/s"),
    MavStream("HIGHRES_IMU", _IMU, "time_usec", _imu_highres, "id", detail="m/s^2, rad/s"),
    MavStream("GPS_RAW_INT", _GNSS, "time_usec", _gps, detail="1e-7 deg, mm, cm/s"),
    MavStream("GPS2_RAW", _GNSS, "time_usec", _gps, instance=1, detail="1e-7 deg, mm, cm/s"),
    MavStream(
        "GLOBAL_POSITION_INT",
        TableName.ESTIMATOR,
        "time_boot_ms",
        _global_position,
        joins=(
            MavJoin("ATTITUDE", "time_boot_ms", _attitude, _ATTITUDE),
            MavJoin("EKF_STATUS_REPORT", None, _ekf_status, ESTIMATOR_TEST_RATIOS),
        ),
        detail="autopilot estimate; attitude from ATTITUDE, test ratios from EKF_STATUS_REPORT",
    ),
    MavStream("SIMSTATE", TableName.TRUTH, None, _simstate, detail="SITL truth (no alt/vel)"),
    MavStream("SIM_STATE", TableName.TRUTH, None, _sim_state, detail="simulator truth"),
    *(
        MavStream(
            name,
            TableName.MAG,
            time,
            convert,
            field,
            instance=inst,
            detail=units,
            suffix=".mag",
            carries=_MAG_FIELDS,
        )
        for name, time, convert, field, inst, units in (
            ("RAW_IMU", "time_usec", _mag_scaled, "id", 0, "mgauss"),
            ("SCALED_IMU", "time_boot_ms", _mag_scaled, None, 0, "mgauss"),
            ("SCALED_IMU2", "time_boot_ms", _mag_scaled, None, 1, "mgauss"),
            ("SCALED_IMU3", "time_boot_ms", _mag_scaled, None, 2, "mgauss"),
            ("HIGHRES_IMU", "time_usec", _mag_highres, "id", 0, "gauss"),
        )
    ),
)

BY_NAME = {s.name: s for s in STREAMS}
BY_MESSAGE: dict[str, tuple[MavStream, ...]] = {}
for _s in STREAMS:
    BY_MESSAGE[_s.message] = (*BY_MESSAGE.get(_s.message, ()), _s)
