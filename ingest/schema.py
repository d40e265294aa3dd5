"""Canonical tables: the contract between every stage (architecture section 2).

One Parquet file per stream per dataset. Time is int64 nanoseconds (``t_ns``) on one declared
time base; the navigation frame is NED and the body frame FRD; units are in the column names.
A null means "not provided by the source", NaN means "provided but invalid"; the two stay
distinct.

``mag`` (optional: only logs with a magnetometer have it) holds the magnetic field in gauss on
the body FRD axes of the ``imu`` table: the same frame conversion and the same mounting
rotation are applied to both, so the field and the specific force can be combined directly
(tilt-compensated heading: ``pipeline.estimation.ins.magheading``).

``gnss_obs`` conventions (what the tightly coupled filters rely on):

- ``sat_{x,y,z}_m`` and ``sat_v{x,y,z}_mps`` are the satellite state at transmit time, expressed
  in the ECEF frame of the receive time (Sagnac / earth-rotation correction applied), so the
  geometric range is ``|sat - rx|``.
- ``sat_clock_m`` is the satellite clock offset times c (relativistic term included, group
  delay applied for single-frequency users); the corrected pseudorange is
  ``pseudorange_m + sat_clock_m - iono_delay_m - tropo_delay_m``.
- ``sat_clock_drift_mps`` likewise corrects ``pseudorange_rate_mps``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc

from navreplay.ingest.errors import TableValidationError

SCHEMA_VERSION = 1


class TableName(StrEnum):
    """Names of the canonical tables (also their file stems: ``imu.parquet`` ...)."""

    IMU = "imu"
    GNSS = "gnss"
    GNSS_OBS = "gnss_obs"
    VEHICLE = "vehicle"
    TRUTH = "truth"
    ESTIMATOR = "estimator"
    MAG = "mag"


class ContextName(StrEnum):
    """Tables of the log's context beside its sensor streams (file stems too): what the
    vehicle said and did (``events``: messages, modes, arming, events, errors) and how its
    IMUs shook (``vibration``). Readers write them where the log has them
    (``LogReader.context``); no stream selection applies to them."""

    EVENTS = "events"
    VIBRATION = "vibration"


class EventKind(StrEnum):
    """``events.kind``: what a row of the events table is."""

    MESSAGE = "message"  # text the vehicle logged or sent (MSG, STATUSTEXT, logged_messages)
    MODE = "mode"  # a flight or drive mode entered; text is its name
    ARMING = "arming"  # "armed" or "disarmed"
    EVENT = "event"  # an autopilot event (ArduPilot EV)
    ERROR = "error"  # a subsystem error or failsafe (ArduPilot ERR)


class FixType:
    """``gnss.fix_type`` values, those of MAVLink ``GPS_FIX_TYPE``."""

    NO_GPS = 0
    NO_FIX = 1
    FIX_2D = 2
    FIX_3D = 3
    DGPS = 4
    RTK_FLOAT = 5
    RTK_FIXED = 6
    STATIC = 7
    PPP = 8


@dataclass(frozen=True)
class Column:
    """One column of a canonical table.

    Attributes:
        name: column name, units in the suffix.
        type: exact Arrow type.
        required: the column must be present.
        nullable: nulls ("not provided") are allowed; NaN ("invalid") is always allowed in floats.
        doc: meaning, frame and units.
    """

    name: str
    type: pa.DataType
    required: bool
    nullable: bool
    doc: str


@dataclass(frozen=True)
class TableSpec:
    """The canonical definition of one table.

    Attributes:
        name: the table name.
        columns: known columns in canonical order.
        key: columns whose tuple must be strictly increasing row to row (sorted and unique).
        extra_float_columns: other float64 columns (e.g. sensor biases in ``truth``) are allowed.
    """

    name: TableName | ContextName
    columns: tuple[Column, ...]
    key: tuple[str, ...]
    extra_float_columns: bool

    @property
    def required(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.columns if c.required)

    def column(self, name: str) -> Column | None:
        for col in self.columns:
            if col.name == name:
                return col
        return None

    def arrow_schema(self, *, optional: bool = True) -> pa.Schema:
        """The Arrow schema: required columns, and the optional ones unless ``optional=False``."""
        return pa.schema(
            [
                pa.field(c.name, c.type, nullable=c.nullable)
                for c in self.columns
                if c.required or optional
            ]
        )


def _f(name: str, doc: str, *, required: bool = True, nullable: bool = False) -> Column:
    return Column(name, pa.float64(), required, nullable, doc)


_T_NS = Column("t_ns", pa.int64(), True, False, "time, int64 ns on the dataset's time base")

_NAV_SOLUTION = (
    _T_NS,
    _f("lat_deg", "geodetic latitude, WGS-84, deg"),
    _f("lon_deg", "geodetic longitude, WGS-84, deg"),
    _f("alt_m", "height above the WGS-84 ellipsoid, m"),
    _f("vel_n_mps", "velocity north, m/s", nullable=True),
    _f("vel_e_mps", "velocity east, m/s", nullable=True),
    _f("vel_d_mps", "velocity down, m/s", nullable=True),
    _f("roll_rad", "roll of body FRD w.r.t. NED, rad", nullable=True),
    _f("pitch_rad", "pitch of body FRD w.r.t. NED, rad", nullable=True),
    _f("yaw_rad", "yaw (heading from north, clockwise) of body FRD, rad", nullable=True),
)
#: The navigation solution's fields after ``t_ns`` (position, NED velocity, attitude), in order.
NAV_SOLUTION_FIELDS = tuple(c.name for c in _NAV_SOLUTION[1:])
#: Extra columns of the ``estimator`` table where the log has them: the onboard EKF's
#: innovation test ratios of velocity, position, height and magnetometer measurements. Above 1
#: the EKF rejected the measurement (ArduPilot's XKF4/NKF4/EKF4 log the square root of the
#: ratio, PX4's estimator_status the ratio).
ESTIMATOR_TEST_RATIOS = ("test_ratio_vel", "test_ratio_pos", "test_ratio_hgt", "test_ratio_mag")
#: ... and its velocity and position innovations as it logs them (ArduPilot XKF3/NKF3/EKF3,
#: PX4 estimator_innovations: the prediction minus the measurement), NED, m/s and m: the
#: velocity and horizontal position are the GNSS measurements', the vertical position that of
#: the EKF's height source (usually the barometer).
ESTIMATOR_INNOVATIONS = (
    "innov_vel_n_mps",
    "innov_vel_e_mps",
    "innov_vel_d_mps",
    "innov_pos_n_m",
    "innov_pos_e_m",
    "innov_pos_d_m",
)

SPECS: Mapping[TableName | ContextName, TableSpec] = {
    TableName.IMU: TableSpec(
        TableName.IMU,
        (
            _T_NS,
            _f("acc_x_mps2", "specific force, body FRD x (forward), m/s^2"),
            _f("acc_y_mps2", "specific force, body FRD y (right), m/s^2"),
            _f("acc_z_mps2", "specific force, body FRD z (down), m/s^2; about -9.8 at rest"),
            _f("gyro_x_radps", "angular rate of body w.r.t. inertial space, FRD x, rad/s"),
            _f("gyro_y_radps", "angular rate, FRD y, rad/s"),
            _f("gyro_z_radps", "angular rate, FRD z, rad/s"),
        ),
        key=("t_ns",),
        extra_float_columns=True,
    ),
    TableName.GNSS: TableSpec(
        TableName.GNSS,
        (
            _T_NS,
            _f("lat_deg", "antenna latitude, WGS-84, deg"),
            _f("lon_deg", "antenna longitude, WGS-84, deg"),
            _f("alt_m", "antenna height above the WGS-84 ellipsoid, m"),
            _f(
                "vel_n_mps",
                "velocity north, m/s (null when the receiver gives none)",
                nullable=True,
            ),
            _f("vel_e_mps", "velocity east, m/s", nullable=True),
            _f("vel_d_mps", "velocity down, m/s", nullable=True),
            _f("h_acc_m", "reported horizontal accuracy (1 sigma), m", nullable=True),
            _f("v_acc_m", "reported vertical accuracy (1 sigma), m", nullable=True),
            _f(
                "speed_acc_mps",
                "reported speed accuracy (1 sigma), m/s",
                required=False,
                nullable=True,
            ),
            Column("fix_type", pa.int8(), True, False, "FixType (MAVLink GPS_FIX_TYPE)"),
            Column("num_sats", pa.int16(), True, True, "satellites used in the fix"),
        ),
        key=("t_ns",),
        extra_float_columns=True,
    ),
    TableName.GNSS_OBS: TableSpec(
        TableName.GNSS_OBS,
        (
            _T_NS,
            Column("sv", pa.string(), True, False, "satellite id, RINEX style: G05, R12, E01"),
            _f("pseudorange_m", "measured pseudorange, m"),
            _f(
                "pseudorange_rate_mps",
                "measured pseudorange rate (-lambda*Doppler), m/s",
                nullable=True,
            ),
            _f("cn0_dbhz", "carrier-to-noise density, dB-Hz", nullable=True),
            _f("sat_x_m", "satellite ECEF x at transmit time, receive-time frame, m"),
            _f("sat_y_m", "satellite ECEF y, m"),
            _f("sat_z_m", "satellite ECEF z, m"),
            _f("sat_vx_mps", "satellite ECEF velocity x, m/s", nullable=True),
            _f("sat_vy_mps", "satellite ECEF velocity y, m/s", nullable=True),
            _f("sat_vz_mps", "satellite ECEF velocity z, m/s", nullable=True),
            _f(
                "sat_clock_m",
                "satellite clock offset * c, added to the pseudorange, m",
                nullable=True,
            ),
            _f("elevation_deg", "elevation at the receiver, deg", nullable=True),
            _f("azimuth_deg", "azimuth at the receiver, clockwise from north, deg", nullable=True),
            _f(
                "sat_clock_drift_mps",
                "satellite clock drift * c, added to the rate, m/s",
                required=False,
                nullable=True,
            ),
            _f("pseudorange_std_m", "pseudorange 1-sigma, m", required=False, nullable=True),
            _f(
                "pseudorange_rate_std_mps",
                "pseudorange-rate 1-sigma, m/s",
                required=False,
                nullable=True,
            ),
            _f("iono_delay_m", "ionospheric delay to subtract, m", required=False, nullable=True),
            _f("tropo_delay_m", "tropospheric delay to subtract, m", required=False, nullable=True),
        ),
        key=("t_ns", "sv"),
        extra_float_columns=True,
    ),
    TableName.VEHICLE: TableSpec(
        TableName.VEHICLE,
        (
            _T_NS,
            _f("speed_mps", "forward speed from wheels or radar, m/s", nullable=True),
            _f(
                "steer_rad",
                "road-wheel steering angle, positive right (FRD yaw sense), rad",
                nullable=True,
            ),
            _f("yaw_rate_radps", "yaw rate about body z (down), rad/s", nullable=True),
        ),
        key=("t_ns",),
        extra_float_columns=True,
    ),
    TableName.TRUTH: TableSpec(
        TableName.TRUTH, _NAV_SOLUTION, key=("t_ns",), extra_float_columns=True
    ),
    TableName.ESTIMATOR: TableSpec(
        TableName.ESTIMATOR, _NAV_SOLUTION, key=("t_ns",), extra_float_columns=True
    ),
    TableName.MAG: TableSpec(
        TableName.MAG,
        (
            _T_NS,
            _f(
                "mag_x_gauss",
                "magnetic flux density, body FRD x (forward), gauss (1 G = 100 uT); the axes "
                "of the imu table (same frame conversion and mounting rotation)",
            ),
            _f("mag_y_gauss", "magnetic flux density, body FRD y (right), gauss"),
            _f("mag_z_gauss", "magnetic flux density, body FRD z (down), gauss"),
        ),
        key=("t_ns",),
        extra_float_columns=True,
    ),
    ContextName.EVENTS: TableSpec(
        ContextName.EVENTS,
        (
            _T_NS,
            Column("seq", pa.int32(), True, False, "order of the rows sharing a t_ns, from 0"),
            Column("kind", pa.string(), True, False, "EventKind: message, mode, arming, ..."),
            Column(
                "severity",
                pa.int8(),
                True,
                True,
                "syslog severity of a message (0 emergency ... 7 debug; MAVLink MAV_SEVERITY, "
                "PX4 log levels); null where the log gives none",
            ),
            Column("text", pa.string(), True, False, "the text as logged (untrusted)"),
            Column("source", pa.string(), True, False, "the log record it came from (MSG, ...)"),
        ),
        key=("t_ns", "seq"),
        extra_float_columns=False,
    ),
    ContextName.VIBRATION: TableSpec(
        ContextName.VIBRATION,
        (
            _T_NS,
            Column("imu", pa.int16(), True, False, "IMU instance, from 0"),
            _f(
                "vibe_x_mps2",
                "vibration level, body x, m/s^2 (ArduPilot VIBE, MAVLink VIBRATION); null where "
                "the log gives another measure (PX4's, as extra columns)",
                nullable=True,
            ),
            _f("vibe_y_mps2", "vibration level, body y, m/s^2", nullable=True),
            _f("vibe_z_mps2", "vibration level, body z, m/s^2", nullable=True),
            _f(
                "clip_count",
                "accelerometer clipping events since boot (cumulative), null where not logged",
                nullable=True,
            ),
        ),
        key=("t_ns", "imu"),
        extra_float_columns=True,
    ),
}
_BY_VALUE: Mapping[str, TableName | ContextName] = {str(k): k for k in SPECS}


def table_name(name: TableName | ContextName | str) -> TableName | ContextName:
    """The enum of a table name (a canonical stream table or a context table).

    Raises:
        TableValidationError: for an unknown name, listing the known ones.
    """
    found = _BY_VALUE.get(str(name))
    if found is None:
        known = ", ".join(_BY_VALUE)
        raise TableValidationError(f"unknown canonical table (known: {known})", table=str(name))
    return found


def spec(name: TableName | ContextName | str) -> TableSpec:
    """The spec of a canonical table; raises ``TableValidationError`` for an unknown name."""
    return SPECS[table_name(name)]


def validate(
    name: TableName | ContextName | str,
    table: pa.Table,
    *,
    previous_key: tuple[Any, ...] | None = None,
) -> None:
    """Check ``table`` against the canonical schema of ``name``.

    Checks, in order: required columns present; exact dtypes; no nulls where not nullable;
    unknown columns only where the table allows extra float64 columns; the key columns strictly
    increasing (sorted, no duplicates), also across a previous chunk whose last key is
    ``previous_key``.

    Raises:
        TableValidationError: naming the table, the column and the first offending row.
    """
    ts = spec(name)
    tname = ts.name.value
    present = set(table.column_names)
    for col_name in ts.required:
        if col_name not in present:
            raise TableValidationError("required column missing", table=tname, column=col_name)
    for field in table.schema:
        col = ts.column(field.name)
        if col is None:
            if not ts.extra_float_columns or field.type != pa.float64():
                raise TableValidationError(
                    f"unknown column of type {field.type}"
                    + (" (extra columns must be float64)" if ts.extra_float_columns else ""),
                    table=tname,
                    column=field.name,
                )
            continue
        if field.type != col.type:
            raise TableValidationError(
                f"wrong dtype {field.type}, expected {col.type}", table=tname, column=field.name
            )
        if not col.nullable and table.column(field.name).null_count:
            row = _first_true(pc.is_null(table.column(field.name)))
            raise TableValidationError(
                "null in a non-nullable column", table=tname, column=field.name, row=row
            )
    _check_key_order(ts, table, previous_key)


def last_key(name: TableName | ContextName | str, table: pa.Table) -> tuple[Any, ...] | None:
    """The key tuple of the last row (for validating a stream chunk by chunk)."""
    if table.num_rows == 0:
        return None
    return tuple(table.column(k)[table.num_rows - 1].as_py() for k in spec(name).key)


def _first_true(mask: pa.ChunkedArray | pa.Array) -> int:
    arr = np.asarray(mask.to_numpy(zero_copy_only=False), dtype=bool)
    return int(np.flatnonzero(arr)[0])


def _check_key_order(ts: TableSpec, table: pa.Table, previous_key: tuple[Any, ...] | None) -> None:
    tname = ts.name.value
    n = table.num_rows
    if n == 0:
        return
    t = table.column("t_ns").to_numpy()
    if previous_key is not None and (t[0], *_secondary(ts, table, 0)) <= previous_key:
        raise TableValidationError(
            f"t_ns {t[0]} does not follow the previous chunk's last key {previous_key}",
            table=tname,
            column="t_ns",
            row=0,
        )
    dt = np.diff(t)
    if len(ts.key) == 1:
        bad = np.flatnonzero(dt <= 0)
        if bad.size:
            row = int(bad[0]) + 1
            what = "duplicate" if dt[bad[0]] == 0 else "unsorted (time goes backwards)"
            raise TableValidationError(
                f"{what} t_ns {t[row]} after {t[row - 1]}", table=tname, column="t_ns", row=row
            )
        return
    backwards = np.flatnonzero(dt < 0)
    if backwards.size:
        row = int(backwards[0]) + 1
        raise TableValidationError(
            f"unsorted t_ns {t[row]} after {t[row - 1]}", table=tname, column="t_ns", row=row
        )
    same = np.flatnonzero(dt == 0)
    if same.size:
        # A secondary key (gnss_obs's sv, events' seq, vibration's imu) decides where t_ns ties.
        sec_name = ts.key[1]
        sec = np.asarray(table.column(sec_name).to_numpy(zero_copy_only=False))
        if sec.dtype.kind == "O":
            sec = sec.astype(str)
        bad = same[sec[same + 1] <= sec[same]]
        if bad.size:
            i = int(bad[0])
            what = "duplicate" if sec[i] == sec[i + 1] else "unsorted"
            raise TableValidationError(
                f"{what} key ({t[i + 1]}, {sec[i + 1]!r}) after ({t[i]}, {sec[i]!r})",
                table=tname,
                column=sec_name,
                row=i + 1,
            )


def _secondary(ts: TableSpec, table: pa.Table, row: int) -> tuple[Any, ...]:
    return tuple(table.column(k)[row].as_py() for k in ts.key[1:])


def from_columns(name: TableName | ContextName | str, columns: Mapping[str, Any]) -> pa.Table:
    """Build a canonical table from column arrays (numpy arrays, lists or Arrow arrays).

    Columns are cast to the canonical types (an unsafe cast, e.g. float to int with a fraction,
    is an error); optional columns that are absent are left out; nullable required columns that
    are absent are filled with nulls ("not provided"). Extra float columns are appended in
    sorted order. The result is validated.

    Raises:
        TableValidationError: for a missing non-nullable column, a failed cast, or any check of
            ``validate``.
    """
    ts = spec(name)
    tname = ts.name.value
    lengths = {len(v) for v in columns.values()}
    if len(lengths) > 1:
        raise TableValidationError(f"columns of different lengths {sorted(lengths)}", table=tname)
    n = lengths.pop() if lengths else 0
    arrays: list[pa.Array] = []
    fields: list[pa.Field] = []
    for col in ts.columns:
        if col.name in columns:
            arrays.append(_to_arrow(tname, col.name, columns[col.name], col.type))
        elif col.required and col.nullable:
            arrays.append(pa.nulls(n, type=col.type))
        elif col.required:
            raise TableValidationError("required column missing", table=tname, column=col.name)
        else:
            continue
        fields.append(pa.field(col.name, col.type, nullable=col.nullable))
    for extra in sorted(set(columns) - {c.name for c in ts.columns}):
        arrays.append(_to_arrow(tname, extra, columns[extra], pa.float64()))
        fields.append(pa.field(extra, pa.float64()))
    table = pa.Table.from_arrays(arrays, schema=pa.schema(fields))
    validate(ts.name, table)
    return table


def _to_arrow(table: str, column: str, values: Any, typ: pa.DataType) -> pa.Array:
    try:
        if isinstance(values, pa.ChunkedArray):
            values = values.combine_chunks()
        if isinstance(values, pa.Array):
            return values.cast(typ, safe=True)
        if (
            isinstance(values, np.ndarray)
            and values.dtype.kind == "f"
            and pa.types.is_floating(typ)
        ):
            # from_pandas=False keeps NaN as a value ("invalid") instead of turning it into null.
            return pa.array(values.astype(np.float64, copy=False), type=typ, from_pandas=False)
        return pa.array(values, type=typ, from_pandas=False)
    except (pa.ArrowInvalid, pa.ArrowTypeError, TypeError, ValueError) as err:
        raise TableValidationError(
            f"cannot store values as {typ}: {err}", table=table, column=column
        ) from err


def empty(name: TableName | ContextName | str) -> pa.Table:
    """An empty table with the full canonical schema (required and optional columns)."""
    return spec(name).arrow_schema().empty_table()
