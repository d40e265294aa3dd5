"""DataFlash messages that feed canonical tables, and their conversion to canonical columns.

Column units are the logged ones after the format-character multipliers (``DfFormat.scaled``):

==========  ===========================================================================
IMU[I]      ``GyrX/Y/Z`` rad/s, ``AccX/Y/Z`` m/s^2, body FRD (also legacy IMU2, IMU3)
GPS[I]      ``Status`` (the MAVLink GPS_FIX_TYPE values), ``GWk``/``GMS`` GPS week and ms of
 + GPA[I]   week (-> t_ns of the fix, GPS time), ``NSats``, ``Lat``/``Lng`` deg, ``Alt`` m
            above MSL, ``Spd`` m/s and ``GCrs`` deg (ground track), ``VZ`` m/s down,
            ``HDop``; GPA of the same instance (nearest in time): ``HAcc``/``VAcc`` m,
            ``SAcc`` m/s (0 = unknown: null), ``VDop`` and ``Und`` (MSL - ellipsoid, m:
            ellipsoidal = Alt - Und)
XKF1[C]     EKF3 (NKF1: EKF2) core C: ``Roll``/``Pitch``/``Yaw`` deg, ``VN/VE/VD`` m/s,
            ``PN/PE/PD`` m from the EKF origin (``ORGN`` type 0, MSL height), placed on the
            earth with ArduPilot's own flat-earth offset (``Location::offset``), so the
            result matches the autopilot's ``POS`` message; ``EKF1`` (2014-2015 NavEKF, no
            ``ORGN`` logged) from an origin estimated from the GPS fixes
SIM         SITL truth: ``Roll/Pitch/Yaw`` deg, ``Lat/Lng`` deg, ``Alt`` m; no velocity
MAG[I]      ``MagX/Y/Z`` milligauss, body FRD, offsets and motor compensation already applied
            (ArduPilot logs the corrected field and the offsets beside it); also legacy
            MAG2, MAG3; rows with ``Health`` 0 are NaN (counted as ``mag_unhealthy``)
IMU.mag     legacy PX4 (sdlog2) ``IMU`` ``MagX/Y/Z`` gauss, body FRD: the same records as the
            IMU stream, a stream of their own (``suffix``) feeding the mag table
==========  ===========================================================================

MSL heights become ellipsoidal with the log's undulation (per row from GPA, else the log's
median) or stay MSL, counted as ``alt_msl_no_geoid``.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from navreplay.ingest.arrays import F64, I64
from navreplay.ingest.readers.mavlink.dfformat import DfFormat
from navreplay.ingest.readers.mavlink.mavmsgs import Converted
from navreplay.ingest.schema import (
    ESTIMATOR_INNOVATIONS,
    ESTIMATOR_TEST_RATIOS,
    FixType,
    TableName,
)

#: ArduPilot's LOCATION_SCALING_FACTOR_INV: 1e-7 degree units per metre (sphere 6378100 m).
LOCATION_SCALING_FACTOR_INV = 89.83204953368922


@dataclass(frozen=True)
class Origin:
    """EKF origins (``ORGN`` type 0) in log order: TimeUS, lat/lon deg, MSL height m."""

    time_us: npt.NDArray[np.int64] = field(default_factory=lambda: np.empty(0, np.int64))
    lat_deg: F64 = field(default_factory=lambda: np.empty(0))
    lon_deg: F64 = field(default_factory=lambda: np.empty(0))
    alt_msl_m: F64 = field(default_factory=lambda: np.empty(0))


@dataclass(frozen=True)
class DfExtras:
    """Per-file facts conversions need: undulation N (ellipsoid = MSL + N) and EKF origins
    (``origin_estimated``: from the GPS fixes, the log having no ``ORGN``)."""

    undulation_m: float | None = None
    origin: Origin = field(default_factory=Origin)
    origin_estimated: bool = False


Convert = Callable[[np.ndarray, DfFormat, DfExtras, I64], Converted]
"""Decoded records, their format, the file's extras and the records' boot time (us)."""


class DfJoin(NamedTuple):
    """A message of the same instance joined to a stream's rows by nearest time: its name, its
    conversion and the columns it adds."""

    message: str
    convert: Convert
    columns: tuple[str, ...]


@dataclass(frozen=True)
class DfStream:
    """A DataFlash message that feeds a canonical table.

    Attributes:
        message: message name.
        table: canonical table.
        convert: decoded records -> canonical columns.
        instance: the instance when the name implies it (legacy ``IMU2``); else the
            ``I``/``C`` column gives it.
        joins: messages of the same instance joined by nearest time, each with its
            conversion, in turn.
        detail: what ``--list`` shows.
        suffix: appended to the message name to name the stream when the message feeds a
            second table (legacy PX4 ``IMU`` -> ``IMU.mag``).
        needs: a column the message's format must have for the stream to exist (``MagX``).
    """

    message: str
    table: TableName
    convert: Convert
    instance: int = 0
    joins: tuple[DfJoin, ...] = ()
    detail: str = ""
    suffix: str = ""
    needs: str = ""

    def present(self, fmt: DfFormat) -> bool:
        """Whether records of format ``fmt`` carry this stream."""
        return not self.needs or self.needs in fmt.columns

    @property
    def name(self) -> str:
        """The stream's name: the message's, with the suffix."""
        return self.message + self.suffix


def _imu(rec: np.ndarray, fmt: DfFormat, _ex: DfExtras, _t: I64) -> Converted:
    gyr = "Gyr" if "GyrX" in fmt.columns else "Gyro"  # legacy PX4: GyroX
    cols = {f"acc_{a}_mps2": fmt.scaled(rec, f"Acc{a.upper()}") for a in "xyz"}
    cols |= {f"gyro_{a}_radps": fmt.scaled(rec, f"{gyr}{a.upper()}") for a in "xyz"}
    return Converted(cols)


def _mag(rec: np.ndarray, fmt: DfFormat, _ex: DfExtras, _t: I64) -> Converted:
    """ArduPilot ``MAG``: milligauss -> gauss; ``Health`` 0 -> NaN (counted)."""
    cols = {f"mag_{a}_gauss": fmt.scaled(rec, f"Mag{a.upper()}") / 1000.0 for a in "xyz"}
    counters: dict[str, int] = {}
    if "Health" in fmt.columns:
        bad = np.asarray(rec["Health"]) == 0
        if bad.any():
            counters["mag_unhealthy"] = int(bad.sum())
            cols = {name: np.where(bad, np.nan, v) for name, v in cols.items()}
    return Converted(cols, counters=counters, info={"units": "milligauss scaled to gauss"})


def _px4_mag(rec: np.ndarray, fmt: DfFormat, _ex: DfExtras, _t: I64) -> Converted:
    """Legacy PX4 (sdlog2) ``IMU`` ``MagX/Y/Z``, gauss."""
    cols = {f"mag_{a}_gauss": fmt.scaled(rec, f"Mag{a.upper()}") for a in "xyz"}
    return Converted(cols, info={"units": "gauss"})


def _msl_to_ellipsoid(alt_msl: F64, und: F64 | None, ex: DfExtras) -> tuple[F64, dict[str, int]]:
    """Ellipsoidal height: per-row undulation where logged (``Und``: MSL - ellipsoid)."""
    n_file = ex.undulation_m
    per_row = (und != 0.0) if und is not None else np.zeros(len(alt_msl), bool)
    n = np.where(per_row, -und if und is not None else 0.0, n_file or 0.0)
    counters: dict[str, int] = {}
    missing = int((~per_row).sum())
    if missing and n_file is None:
        counters["alt_msl_no_geoid"] = missing
    return alt_msl + n, counters


def _gps(rec: np.ndarray, fmt: DfFormat, ex: DfExtras, _t: I64) -> Converted:
    speed = fmt.scaled(rec, "Spd")
    course = np.radians(fmt.scaled(rec, "GCrs"))
    fix = np.asarray(rec["Status"], dtype=np.int8)
    n = len(rec)
    cols = {
        "lat_deg": fmt.scaled(rec, "Lat"),
        "lon_deg": fmt.scaled(rec, "Lng"),
        "alt_msl": fmt.scaled(rec, "Alt"),
        "vel_n_mps": speed * np.cos(course),
        "vel_e_mps": speed * np.sin(course),
        "vel_d_mps": fmt.scaled(rec, "VZ") if "VZ" in fmt.columns else np.zeros(n),
        "fix_type": fix,
        "num_sats": np.asarray(rec["NSats"], dtype=np.int16),
        "hdop": fmt.scaled(rec, "HDop") if "HDop" in fmt.columns else np.full(n, np.nan),
    }
    nulls = {} if "VZ" in fmt.columns else {"vel_d_mps": np.ones(n, bool)}
    return Converted(cols, nulls, counters={"no_fix": int((fix < FixType.FIX_2D).sum())})


def _px4_gps(rec: np.ndarray, fmt: DfFormat, _ex: DfExtras, _t: I64) -> Converted:
    """Legacy PX4 (sdlog2) ``GPS``: ``Fix``, ``Lat/Lon`` deg, ``Alt`` m MSL, ``VelN/E/D``
    m/s, ``EPH/EPV`` m (PX4's accuracies), ``nSat``; no geoid: heights stay MSL."""
    fix = np.asarray(rec["Fix"], dtype=np.int8)
    n = len(rec)
    cols = {
        "lat_deg": fmt.scaled(rec, "Lat"),
        "lon_deg": fmt.scaled(rec, "Lon"),
        "alt_msl": fmt.scaled(rec, "Alt"),
        **{f"vel_{a}_mps": fmt.scaled(rec, f"Vel{a.upper()}") for a in "ned"},
        "fix_type": fix,
        "num_sats": np.asarray(rec["nSat"], dtype=np.int16),
        "h_acc_m": fmt.scaled(rec, "EPH"),
        "v_acc_m": fmt.scaled(rec, "EPV"),
        "speed_acc_mps": np.zeros(n),
        "und": np.zeros(n),
    }
    nulls = {"speed_acc_mps": np.ones(n, bool)}
    return Converted(cols, nulls, counters={"no_fix": int((fix < FixType.FIX_2D).sum())})


def _gpa(rec: np.ndarray, fmt: DfFormat, _ex: DfExtras, _t: I64) -> Converted:
    cols = {
        "h_acc_m": fmt.scaled(rec, "HAcc"),
        "v_acc_m": fmt.scaled(rec, "VAcc"),
        "speed_acc_mps": fmt.scaled(rec, "SAcc"),
        "und": fmt.scaled(rec, "Und") if "Und" in fmt.columns else np.zeros(len(rec)),
        "vdop": fmt.scaled(rec, "VDop") if "VDop" in fmt.columns else np.full(len(rec), np.nan),
    }
    return Converted(cols)


def finish_gnss(c: Converted, ex: DfExtras) -> None:
    """After the GPA join: heights to ellipsoidal, accuracies of 0 to null."""
    cols, nulls = c.columns, c.nulls
    und = cols.pop("und")
    und = np.where(nulls.pop("und", np.zeros(len(und), bool)), 0.0, und)
    alt, counters = _msl_to_ellipsoid(cols.pop("alt_msl"), und, ex)
    cols["alt_m"] = alt
    for name, n in counters.items():
        c.counters[name] = c.counters.get(name, 0) + n
    for name in ("h_acc_m", "v_acc_m", "speed_acc_mps"):
        nulls[name] = nulls.get(name, np.zeros(len(alt), bool)) | (cols[name] <= 0.0)
        cols[name] = np.where(nulls[name], 0.0, cols[name])


def _wrap(angle: F64) -> F64:
    return np.asarray((angle + math.pi) % (2 * math.pi) - math.pi, dtype=np.float64)


def _attitude(rec: np.ndarray, fmt: DfFormat) -> dict[str, F64]:
    return {
        "roll_rad": np.radians(fmt.scaled(rec, "Roll")),
        "pitch_rad": np.radians(fmt.scaled(rec, "Pitch")),
        "yaw_rad": _wrap(np.radians(fmt.scaled(rec, "Yaw"))),
    }


def _ekf(rec: np.ndarray, fmt: DfFormat, ex: DfExtras, t_us: I64) -> Converted:
    o = ex.origin
    n = len(rec)
    if not len(o.time_us):
        nan = np.full(n, np.nan)
        lat, lon, alt_msl = nan, nan, nan
        counters = {"no_ekf_origin": n}
    else:
        k = np.maximum(np.searchsorted(o.time_us, t_us, side="right") - 1, 0)
        pn, pe = fmt.scaled(rec, "PN"), fmt.scaled(rec, "PE")
        dlat = pn * LOCATION_SCALING_FACTOR_INV * 1e-7
        lat = o.lat_deg[k] + dlat
        scale = np.maximum(np.cos(np.radians(o.lat_deg[k] + dlat / 2)), 0.01)
        lon = o.lon_deg[k] + pe * LOCATION_SCALING_FACTOR_INV * 1e-7 / scale
        alt_msl = o.alt_msl_m[k] - fmt.scaled(rec, "PD")
        counters = {"ekf_origin_estimated_from_gps": n} if ex.origin_estimated else {}
    alt, more = _msl_to_ellipsoid(alt_msl, None, ex)
    cols = {
        "lat_deg": lat,
        "lon_deg": lon,
        "alt_m": alt,
        "vel_n_mps": fmt.scaled(rec, "VN"),
        "vel_e_mps": fmt.scaled(rec, "VE"),
        "vel_d_mps": fmt.scaled(rec, "VD"),
        **_attitude(rec, fmt),
    }
    return Converted(cols, counters=counters | more)


#: the onboard EKF's innovation test ratios (XKF4/NKF4/EKF4 ``SV``, ``SP``, ``SH``, ``SM``;
#: the legacy EKF4's largest of ``SMX/SMY/SMZ``): a measurement is rejected above 1
TEST_RATIOS = ESTIMATOR_TEST_RATIOS


def _ekf_tests(rec: np.ndarray, fmt: DfFormat, _ex: DfExtras, _t: I64) -> Converted:
    mag_fields = (
        ["SM"] if "SM" in fmt.columns else [c for c in ("SMX", "SMY", "SMZ") if c in fmt.columns]
    )
    nan = np.full(len(rec), np.nan)
    mag = np.max([fmt.scaled(rec, c) for c in mag_fields], axis=0) if mag_fields else nan
    cols = {
        name: fmt.scaled(rec, field) if field in fmt.columns else nan
        for name, field in zip(TEST_RATIOS[:3], ("SV", "SP", "SH"), strict=True)
    }
    return Converted(cols | {"test_ratio_mag": np.asarray(mag, dtype=np.float64)})


def _ekf_innovations(rec: np.ndarray, fmt: DfFormat, _ex: DfExtras, _t: I64) -> Converted:
    nan = np.full(len(rec), np.nan)
    fields = ("IVN", "IVE", "IVD", "IPN", "IPE", "IPD")
    return Converted({
        name: fmt.scaled(rec, f) if f in fmt.columns else nan
        for name, f in zip(ESTIMATOR_INNOVATIONS, fields, strict=True)
    })  # fmt: skip


def _ekf_joins(n: str) -> tuple[DfJoin, ...]:
    """The test ratios (``<x>KF4``) and GNSS innovations (``<x>KF3``) of an EKF's core."""
    return (
        DfJoin(f"{n}4", _ekf_tests, TEST_RATIOS),
        DfJoin(f"{n}3", _ekf_innovations, ESTIMATOR_INNOVATIONS),
    )


def _sim(rec: np.ndarray, fmt: DfFormat, ex: DfExtras, _t: I64) -> Converted:
    alt, counters = _msl_to_ellipsoid(fmt.scaled(rec, "Alt"), None, ex)
    cols = {
        "lat_deg": fmt.scaled(rec, "Lat"),
        "lon_deg": fmt.scaled(rec, "Lng"),
        "alt_m": alt,
        **_attitude(rec, fmt),
    }
    return Converted(cols, counters=counters)


#: the GPA columns joined into GPS
JOIN_COLUMNS = ("h_acc_m", "v_acc_m", "speed_acc_mps", "und", "vdop")
_GPA = DfJoin("GPA", _gpa, JOIN_COLUMNS)
_IMU = TableName.IMU
_EST = TableName.ESTIMATOR
_MAG = TableName.MAG
STREAMS: tuple[DfStream, ...] = (
    DfStream("IMU", _IMU, _imu, detail="rad/s, m/s^2"),
    DfStream("IMU2", _IMU, _imu, instance=1, detail="rad/s, m/s^2 (legacy second IMU)"),
    DfStream("IMU3", _IMU, _imu, instance=2, detail="rad/s, m/s^2 (legacy third IMU)"),
    DfStream("GPS", TableName.GNSS, _gps, joins=(_GPA,), detail="GPS week and ms -> GPS time"),
    DfStream(
        "GPS2",
        TableName.GNSS,
        _gps,
        instance=1,
        joins=(DfJoin("GPA2", _gpa, JOIN_COLUMNS),),
        detail="legacy 2nd GPS",
    ),
    DfStream(
        "XKF1",
        _EST,
        _ekf,
        joins=_ekf_joins("XKF"),
        detail="EKF3 core output, position from ORGN; test ratios from XKF4, innovations from XKF3",
    ),
    DfStream(
        "NKF1",
        _EST,
        _ekf,
        joins=_ekf_joins("NKF"),
        detail="EKF2 core output, position from ORGN; test ratios from NKF4, innovations from NKF3",
    ),
    DfStream(
        "EKF1",
        _EST,
        _ekf,
        joins=_ekf_joins("EKF"),
        detail="EKF (2014-2015 NavEKF) output, position from ORGN; EKF4 tests, EKF3 innovations",
    ),
    DfStream("SIM", TableName.TRUTH, _sim, detail="SITL truth (no velocity)"),
    DfStream("MAG", _MAG, _mag, detail="milligauss -> gauss, body FRD"),
    DfStream("MAG2", _MAG, _mag, instance=1, detail="milligauss (legacy second compass)"),
    DfStream("MAG3", _MAG, _mag, instance=2, detail="milligauss (legacy third compass)"),
)
BY_NAME = {s.name: s for s in STREAMS}

#: Legacy PX4 (sdlog2, ``.px4log``, until 2016): the same framing, PX4's own messages; the
#: IMUs are ``IMU``, ``IMU1``, ``IMU2``; records are timed by the ``TIME`` record before them.
PX4_STREAMS: tuple[DfStream, ...] = (
    DfStream("IMU", _IMU, _imu, detail="rad/s, m/s^2 (PX4 sdlog2)"),
    DfStream("IMU1", _IMU, _imu, instance=1, detail="rad/s, m/s^2 (PX4 sdlog2, second IMU)"),
    DfStream("IMU2", _IMU, _imu, instance=2, detail="rad/s, m/s^2 (PX4 sdlog2, third IMU)"),
    DfStream("GPS", TableName.GNSS, _px4_gps, detail="TIME paired with GPSTime (UTC); EPH/EPV"),
    DfStream(
        "IMU",
        _MAG,
        _px4_mag,
        detail="MagX/Y/Z gauss of the IMU records",
        suffix=".mag",
        needs="MagX",
    ),
    DfStream(
        "IMU1",
        _MAG,
        _px4_mag,
        instance=1,
        detail="gauss (second IMU's compass)",
        suffix=".mag",
        needs="MagX",
    ),
    DfStream(
        "IMU2",
        _MAG,
        _px4_mag,
        instance=2,
        detail="gauss (third IMU's compass)",
        suffix=".mag",
        needs="MagX",
    ),
)
PX4_BY_NAME = {s.name: s for s in PX4_STREAMS}


def by_message(specs: dict[str, DfStream]) -> dict[str, tuple[DfStream, ...]]:
    """The streams of each message (a legacy PX4 ``IMU`` feeds both imu and mag)."""
    out: dict[str, tuple[DfStream, ...]] = {}
    for spec in specs.values():
        out[spec.message] = (*out.get(spec.message, ()), spec)
    return out


BY_MESSAGE = by_message(BY_NAME)
PX4_BY_MESSAGE = by_message(PX4_BY_NAME)
