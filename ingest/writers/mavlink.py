"""MAVLink telemetry logs (``.tlog``) from canonical tables, with pymavlink's own encoder.

A tlog is what Mission Planner, QGroundControl and MAVProxy record: repeated
``[8-byte big-endian UNIX time, microseconds][MAVLink packet]``. Packets are MAVLink 2 frames
of the ``ardupilotmega`` dialect from one system/component with a running sequence number.

Message mapping (canonical tables use ``t_ns`` on the UNIX clock; every ``time_usec`` field and
every tlog stamp is that time in microseconds):

- ``imu`` -> ``HIGHRES_IMU``: specific force (m/s^2) and angular rate (rad/s) in body FRD as
  float32, ``fields_updated = 0x3F`` (accelerometer and gyro only); with ``mag_gauss``, the
  magnetic field in body FRD (gauss) in ``xmag/ymag/zmag`` and ``fields_updated = 0x1FF``.
- ``gnss`` -> ``GPS_RAW_INT``: lat/lon in 1e-7 deg, ``alt`` and ``alt_ellipsoid`` in mm (no
  geoid model: both carry the ellipsoidal height), ``vel`` ground speed in cm/s and ``cog`` in
  cdeg from ``vel_n/vel_e`` (UINT16_MAX when unknown; ``cog`` also when the speed rounds to 0),
  ``h_acc``/``v_acc`` in mm and ``vel_acc`` in mm/s (0 = unknown), ``eph``/``epv`` UINT16_MAX
  (no DOP simulated), ``satellites_visible`` UINT8_MAX when unknown. ``vel_d`` has no field.
- ``truth`` -> ``SIMSTATE`` (ArduPilot SITL's truth message: attitude, true IMU, lat/lng in
  1e-7 deg) and ``SIM_STATE`` (common set: quaternion, attitude, lat/lon/alt, NED velocity,
  ``lat_int/lon_int`` in 1e-7 deg), both at each truth sample (or those of ``truth_messages``).
- ``HEARTBEAT`` (``base_mode`` with the armed flag when ``armed``) and ``SYSTEM_TIME`` once per
  second from the first record.

``as_logged_imu`` and ``as_logged_gnss`` return the canonical tables exactly as a reader decodes
them from the log (float32 IMU, integer-scaled GNSS), so callers can keep reference tables
identical to the file.
"""

from __future__ import annotations

import struct
from collections.abc import Iterator
from pathlib import Path
from typing import IO, Any

import numpy as np
import numpy.typing as npt
import pyarrow as pa
from pymavlink.dialects.v20 import ardupilotmega as mavlink

from navreplay.ingest.arrays import F64
from navreplay.ingest.atomic import AtomicWriter
from navreplay.ingest.errors import IngestError
from navreplay.ingest.schema import NAV_SOLUTION_FIELDS, from_columns

UINT8_MAX = 255
UINT16_MAX = 65535
_STAMP = struct.Struct(">Q")
MAV_TYPE_GENERIC = mavlink.MAV_TYPE_GENERIC
MAV_TYPE_FIXED_WING = mavlink.MAV_TYPE_FIXED_WING
MAV_TYPE_GROUND_ROVER = mavlink.MAV_TYPE_GROUND_ROVER
MAV_TYPE_QUADROTOR = mavlink.MAV_TYPE_QUADROTOR
#: HIGHRES_IMU.fields_updated: xacc, yacc, zacc, xgyro, ygyro, zgyro.
HIGHRES_IMU_ACC_GYRO = 0x3F
#: HIGHRES_IMU.fields_updated: the above and xmag, ymag, zmag.
HIGHRES_IMU_ACC_GYRO_MAG = 0x1FF
#: the truth messages ``write_tlog`` can write
TRUTH_MESSAGES = ("SIMSTATE", "SIM_STATE")
_ARMED_MODE = mavlink.MAV_MODE_FLAG_SAFETY_ARMED | mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED


class TlogWriter(AtomicWriter):
    """Write a tlog atomically: the file appears complete at ``path`` on success only.

    Use as a context manager; ``write(t_unix_us, msg)`` appends one stamped packet, where
    ``msg`` comes from ``writer.mav.<name>_encode(...)``.

    Args:
        path: target ``.tlog`` file.
        system_id, component_id: the sender of every packet.
    """

    def __init__(self, path: str | Path, *, system_id: int = 1, component_id: int = 1) -> None:
        self.path = Path(path)
        self.mav = mavlink.MAVLink(None, srcSystem=system_id, srcComponent=component_id)
        self.packets = 0
        self._fh: IO[bytes] | None = None
        self._last_us = -1

    def _start(self, tmp: Path) -> None:
        self._fh = tmp.open("wb")

    def write(self, t_unix_us: int, msg: mavlink.MAVLink_message) -> None:
        """Append ``msg`` stamped ``t_unix_us``; stamps must not decrease."""
        if self._fh is None:
            raise RuntimeError("TlogWriter.write outside its `with` block")
        if t_unix_us < self._last_us:
            raise IngestError(
                f"tlog stamp {t_unix_us} us precedes the previous {self._last_us} us",
                path=self.path,
                record=msg.get_type(),
            )
        self._last_us = t_unix_us
        packet = msg.pack(self.mav)
        self.mav.seq = (self.mav.seq + 1) % 256  # what MAVLink.send does after packing
        self._fh.write(_STAMP.pack(t_unix_us) + packet)
        self.packets += 1

    def _finish(self, ok: bool) -> None:
        if self._fh is not None:
            self._fh.close()
            self._fh = None


def _us(table: pa.Table, name: str, path: Path) -> npt.NDArray[np.int64]:
    t_ns = table.column("t_ns").to_numpy()
    if np.any(t_ns % 1000):
        raise IngestError(
            f"{name} t_ns is not a whole number of microseconds", path=path, record=name
        )
    out: npt.NDArray[np.int64] = t_ns // 1000
    return out


def _col(table: pa.Table, name: str) -> F64:
    """A float column as float64 with nulls as NaN."""
    col = table.column(name)
    return np.asarray(col.to_numpy(zero_copy_only=False), dtype=np.float64)


def _gps_fields(gnss: pa.Table) -> dict[str, npt.NDArray[np.int64]]:
    """Integer GPS_RAW_INT fields for every gnss row."""
    vn, ve = _col(gnss, "vel_n_mps"), _col(gnss, "vel_e_mps")
    known = np.isfinite(vn) & np.isfinite(ve)
    speed_cms = np.where(known, np.rint(np.hypot(vn, ve) * 100.0), UINT16_MAX)
    speed_cms = np.minimum(speed_cms, UINT16_MAX - 1, where=known, out=speed_cms)
    cog = np.rint(np.degrees(np.arctan2(ve, vn)) % 360.0 * 100.0) % 36000
    cog = np.where(known & (speed_cms > 0), cog, UINT16_MAX)

    def mm(name: str, scale: float = 1000.0) -> npt.NDArray[np.int64]:
        if name not in gnss.column_names:
            return np.zeros(gnss.num_rows, dtype=np.int64)
        v = _col(gnss, name)
        return np.where(np.isfinite(v), np.rint(v * scale), 0).astype(np.int64)

    sats = gnss.column("num_sats").fill_null(UINT8_MAX).to_numpy().astype(np.int64)
    return {
        "fix_type": gnss.column("fix_type").to_numpy().astype(np.int64),
        "lat": np.rint(_col(gnss, "lat_deg") * 1e7).astype(np.int64),
        "lon": np.rint(_col(gnss, "lon_deg") * 1e7).astype(np.int64),
        "alt": mm("alt_m"),
        "vel": speed_cms.astype(np.int64),
        "cog": cog.astype(np.int64),
        "satellites_visible": np.clip(sats, 0, UINT8_MAX),
        "h_acc": mm("h_acc_m"),
        "v_acc": mm("v_acc_m"),
        "vel_acc": mm("speed_acc_mps"),
    }


def as_logged_gnss(gnss: pa.Table) -> pa.Table:
    """The gnss table as decoded from the GPS_RAW_INT messages ``write_tlog`` writes.

    ``vel_d_mps`` becomes null (no field); unknown speed/course, accuracies of 0 and
    ``satellites_visible`` UINT8_MAX become null.
    """
    f = _gps_fields(gnss)
    n = gnss.num_rows
    speed = np.where(f["vel"] == UINT16_MAX, np.nan, f["vel"] / 100.0)
    cog = np.where(f["cog"] == UINT16_MAX, 0.0, np.radians(f["cog"] / 100.0))

    def nullable(values: F64, unknown: npt.NDArray[np.bool_]) -> pa.Array:
        return pa.array(values, mask=unknown, type=pa.float64())

    no_vel = np.isnan(speed)
    return from_columns(
        "gnss",
        {
            "t_ns": gnss.column("t_ns"),
            "lat_deg": f["lat"] / 1e7,
            "lon_deg": f["lon"] / 1e7,
            "alt_m": f["alt"] / 1000.0,
            "vel_n_mps": nullable(np.nan_to_num(speed) * np.cos(cog), no_vel),
            "vel_e_mps": nullable(np.nan_to_num(speed) * np.sin(cog), no_vel),
            "vel_d_mps": pa.nulls(n, pa.float64()),
            "h_acc_m": nullable(f["h_acc"] / 1000.0, f["h_acc"] == 0),
            "v_acc_m": nullable(f["v_acc"] / 1000.0, f["v_acc"] == 0),
            "speed_acc_mps": nullable(f["vel_acc"] / 1000.0, f["vel_acc"] == 0),
            "fix_type": f["fix_type"].astype(np.int8),
            "num_sats": pa.array(
                f["satellites_visible"], mask=f["satellites_visible"] == UINT8_MAX, type=pa.int16()
            ),
        },
    )


_IMU_COLS = (
    "acc_x_mps2",
    "acc_y_mps2",
    "acc_z_mps2",
    "gyro_x_radps",
    "gyro_y_radps",
    "gyro_z_radps",
)


def as_logged_imu(imu: pa.Table) -> pa.Table:
    """The imu table as decoded from HIGHRES_IMU (float32 values)."""
    cols: dict[str, Any] = {"t_ns": imu.column("t_ns")}
    for name in _IMU_COLS:
        cols[name] = _col(imu, name).astype(np.float32).astype(np.float64)
    return from_columns("imu", cols)


def _events(
    imu: pa.Table | None, gnss: pa.Table | None, truth: pa.Table | None, path: Path
) -> Iterator[tuple[int, int, int]]:
    """(t_us, stream, row) in time order; at equal times imu, truth, gnss."""
    parts = []
    for stream, table in enumerate((imu, truth, gnss)):
        if table is not None and table.num_rows:
            t = _us(table, ("imu", "truth", "gnss")[stream], path)
            parts.append(np.stack([t, np.full(t.size, stream), np.arange(t.size)], axis=1))
    if not parts:
        return iter(())
    ev = np.concatenate(parts)
    ev = ev[np.lexsort((ev[:, 2], ev[:, 1], ev[:, 0]))]
    return ((int(a), int(b), int(c)) for a, b, c in ev.tolist())


def write_tlog(
    path: str | Path,
    *,
    imu: pa.Table | None = None,
    gnss: pa.Table | None = None,
    truth: pa.Table | None = None,
    truth_imu: pa.Table | None = None,
    mav_type: int = MAV_TYPE_GENERIC,
    mag_gauss: F64 | None = None,
    truth_messages: tuple[str, ...] = TRUTH_MESSAGES,
    armed: bool = False,
) -> int:
    """Write canonical tables as a tlog (see the module docstring); returns the packet count.

    Args:
        path: target file, written atomically.
        imu, gnss, truth: canonical tables; ``t_ns`` on the UNIX clock, whole microseconds.
        truth_imu: the error-free specific force and rate at the truth rows (an imu table with
            the same ``t_ns``) for the SIMSTATE/SIM_STATE acceleration and gyro fields; zeros
            when absent.
        mav_type: ``MAV_TYPE`` of the HEARTBEAT.
        mag_gauss: the magnetic field in body FRD, gauss, one row per imu row (n, 3), for the
            HIGHRES_IMU ``xmag/ymag/zmag`` fields.
        truth_messages: which of ``TRUTH_MESSAGES`` carry the truth.
        armed: the HEARTBEAT says the vehicle is armed (``MAV_MODE_FLAG_SAFETY_ARMED``).

    Raises:
        IngestError: times are not whole microseconds, truth_imu does not match truth, or
            mag_gauss does not match imu.
    """
    path = Path(path)
    imu_v = np.stack([_col(imu, c) for c in _IMU_COLS], axis=1) if imu is not None else None
    mag = _mag_fields(imu, mag_gauss, path)
    unknown = set(truth_messages) - set(TRUTH_MESSAGES)
    if unknown:
        raise ValueError(f"truth_messages: {sorted(unknown)} not among {TRUTH_MESSAGES}")
    base_mode = _ARMED_MODE if armed else 0
    gps = _gps_fields(gnss) if gnss is not None else None
    tr = _truth_fields(truth, truth_imu, path) if truth is not None else None
    with TlogWriter(path) as w:
        mav = w.mav
        next_beat = None
        t0 = None
        for t_us, stream, i in _events(imu, gnss, truth, path):
            if next_beat is None or t_us >= next_beat:
                t0 = t_us if t0 is None else t0
                w.write(
                    t_us,
                    mav.heartbeat_encode(
                        mav_type,
                        mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA,
                        base_mode,
                        0,
                        mavlink.MAV_STATE_ACTIVE,
                    ),
                )
                w.write(t_us, mav.system_time_encode(t_us, (t_us - t0) // 1000))
                next_beat = t0 + ((t_us - t0) // 1_000_000 + 1) * 1_000_000
            if stream == 0 and imu_v is not None:
                a = imu_v[i].tolist()
                m, updated = (
                    ([0.0, 0.0, 0.0], HIGHRES_IMU_ACC_GYRO)
                    if mag is None
                    else (mag[i].tolist(), HIGHRES_IMU_ACC_GYRO_MAG)
                )
                w.write(
                    t_us,
                    mav.highres_imu_encode(t_us, *a, *m, 0.0, 0.0, 0.0, 0.0, updated, 0),
                )
            elif stream == 1 and tr is not None:
                _write_truth(w, t_us, tr, i, truth_messages)
            elif stream == 2 and gps is not None:
                g = {k: int(v[i]) for k, v in gps.items()}
                w.write(
                    t_us,
                    mav.gps_raw_int_encode(
                        t_us,
                        g["fix_type"],
                        g["lat"],
                        g["lon"],
                        g["alt"],
                        UINT16_MAX,
                        UINT16_MAX,
                        g["vel"],
                        g["cog"],
                        g["satellites_visible"],
                        alt_ellipsoid=g["alt"],
                        h_acc=g["h_acc"],
                        v_acc=g["v_acc"],
                        vel_acc=g["vel_acc"],
                    ),
                )
        return w.packets


def _mag_fields(imu: pa.Table | None, mag_gauss: F64 | None, path: Path) -> F64 | None:
    if mag_gauss is None:
        return None
    mag = np.asarray(mag_gauss, dtype=np.float64)
    if imu is None or mag.shape != (imu.num_rows, 3):
        rows = 0 if imu is None else imu.num_rows
        raise IngestError(
            f"mag_gauss has shape {mag.shape}; the imu table needs ({rows}, 3)", path=path
        )
    return mag


def _truth_fields(truth: pa.Table, truth_imu: pa.Table | None, path: Path) -> dict[str, F64]:
    n = truth.num_rows
    out = {c: np.nan_to_num(_col(truth, c)) for c in NAV_SOLUTION_FIELDS}
    if truth_imu is not None:
        same = truth_imu.num_rows == n and np.array_equal(
            truth_imu.column("t_ns").to_numpy(), truth.column("t_ns").to_numpy()
        )
        if not same:
            raise IngestError("truth_imu must have the truth table's t_ns", path=path)
        for c in _IMU_COLS:
            out[c] = _col(truth_imu, c)
    else:
        for c in _IMU_COLS:
            out[c] = np.zeros(n)
    out["q"] = _euler_to_quat(out["roll_rad"], out["pitch_rad"], out["yaw_rad"])
    return out


def _euler_to_quat(roll: F64, pitch: F64, yaw: F64) -> F64:
    """ZYX Euler angles to Hamilton quaternions [w, x, y, z], shape (n, 4)."""
    cr, sr = np.cos(roll / 2), np.sin(roll / 2)
    cp, sp = np.cos(pitch / 2), np.sin(pitch / 2)
    cy, sy = np.cos(yaw / 2), np.sin(yaw / 2)
    return np.stack(
        [
            cr * cp * cy + sr * sp * sy,
            sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
        ],
        axis=1,
    )


def _write_truth(
    w: TlogWriter, t_us: int, tr: dict[str, F64], i: int, messages: tuple[str, ...]
) -> None:
    rpy = [float(tr[c][i]) for c in ("roll_rad", "pitch_rad", "yaw_rad")]
    imu = [float(tr[c][i]) for c in _IMU_COLS]
    lat, lon = float(tr["lat_deg"][i]), float(tr["lon_deg"][i])
    lat_e7, lon_e7 = round(lat * 1e7), round(lon * 1e7)
    if "SIMSTATE" in messages:
        w.write(t_us, w.mav.simstate_encode(*rpy, *imu, lat_e7, lon_e7))
    if "SIM_STATE" not in messages:
        return
    q = tr["q"][i].tolist()
    vel = [float(tr[c][i]) for c in ("vel_n_mps", "vel_e_mps", "vel_d_mps")]
    w.write(
        t_us,
        w.mav.sim_state_encode(
            *q, *rpy, *imu, lat, lon, float(tr["alt_m"][i]), 0.0, 0.0, *vel, lat_e7, lon_e7
        ),
    )
