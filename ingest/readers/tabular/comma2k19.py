"""comma2k19 segments: NumPy arrays (``.npy`` without extension) in a fixed directory layout.

A segment directory (``<route>/<n>/`` upstream) holds ``processed_log/<group>/<stream>/{t,
value}`` and ``global_pose/frame_*``. What becomes which table:

=====================  ==========  =============================================================
stream                 table       conversion
=====================  ==========  =============================================================
IMU                    imu         ``accelerometer`` (specific force) and ``gyro`` (Android
                                   bias-corrected rate), axes [forward, right, down] = FRD as
                                   recorded; ``gyro_uncalibrated``/``gyro_bias`` not used
GNSS/live_gnss_ublox   gnss        [lat, lon, speed, utc_ms, alt, bearing]: alt is ellipsoidal
GNSS/live_gnss_qcom    gnss        (checked against the reference pose); speed + bearing ->
                                   vel_n/vel_e, vel_d not provided; no accuracy or satellite
                                   count in the log (null); fix_type 3-D for every finite fix
CAN                    vehicle     ``speed`` -> speed_mps, ``wheel_speed`` -> wheel_{fl,fr,rl,rr}
                                   _mps; ``steering_angle`` (steering-wheel angle in degrees,
                                   positive counter-clockwise = left, inferred from the gyro's
                                   yaw rate) -> steer_wheel_rad positive right (FRD), and
                                   steer_rad = steer_wheel_rad / vehicle.steer_ratio when the
                                   descriptor gives the ratio (else null). Steering has its own
                                   stamps: rows are the union of both, the other column null.
global_pose            truth       comma's post-processed pose of the ROAD CAMERA (not of the
                                   IMU or antenna; lever arms unknown): ECEF position ->
                                   lat/lon/alt, ECEF velocity -> NED, quaternion (scalar first,
                                   camera [forward, right, down] -> ECEF) -> roll/pitch/yaw
GNSS/raw_gnss_*        (none)      pseudoranges without ephemeris: listed, not converted
IMU/magnetometer*      (none)      no canonical table
=====================  ==========  =============================================================

Time: processed_log streams are stamped on the device's boot clock (s). ``global_pose`` pairs
it with GPS time (``frame_times`` with ``frame_gps_times`` = [week, time of week]); every
stream is converted with that pairing and declared GPS. A GNSS fix is stamped with its
arrival on the boot clock, like every stream, and its own UTC epoch (leap seconds applied) is
kept as ``latency_s`` = arrival - epoch (~0.2 s for the u-blox). Without ``global_pose`` the
streams stay on the boot clock (``recorder``).

Row offsets are the byte offsets of each row in its stream's ``t`` file.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import numpy.typing as npt

from navreplay.ingest.arrays import F64, I64, Bools
from navreplay.ingest.damage import Completeness, Defect
from navreplay.ingest.detect import Detected, Format
from navreplay.ingest.ecef import (
    c_ned_ecef,
    dcm_from_quat_wxyz,
    geodetic_from_ecef,
    rpy_from_dcm,
    velocity_ned_from_course,
)
from navreplay.ingest.errors import CorruptLogError
from navreplay.ingest.platform import Platform
from navreplay.ingest.readers.base import (
    Batch,
    Inventory,
    LogReader,
    ReadContext,
    Selection,
    StreamInfo,
)
from navreplay.ingest.readers.tabular import _npy
from navreplay.ingest.schema import FixType, TableName
from navreplay.ingest.timebase import NS_PER_S, SECONDS_PER_WEEK, TimeBase, utc_to_gps_ns

#: comma2k19 is recorded by comma.ai's devices in cars
PLATFORM = Platform("ground", "comma2k19 (a car dataset)")
NO_EPHEMERIS = (
    "raw pseudoranges (u-blox/Qualcomm) not convertible to gnss_obs: the segment carries no "
    "broadcast ephemeris, so satellite positions and clocks are unknown"
)
CAMERA_POSE = (
    "truth is comma's post-processed pose of the road camera (axes [forward, right, down]), "
    "not of the IMU or antenna; lever arms unknown; not survey-grade"
)


@dataclass(frozen=True)
class _Spec:
    key: str
    folder: str
    table: TableName | None
    frame: str | None
    msgtype: str
    detail: str


_LOG = "processed_log"
_SPECS = (
    _Spec(
        "IMU",
        f"{_LOG}/IMU/accelerometer",
        TableName.IMU,
        "frd",
        "accelerometer+gyro",
        "specific force and bias-corrected rate, [forward, right, down]",
    ),
    _Spec(
        "GNSS/live_gnss_ublox",
        f"{_LOG}/GNSS/live_gnss_ublox",
        TableName.GNSS,
        "ned",
        "live_gnss",
        "u-blox fixes: lat, lon, speed, utc_ms, alt, bearing",
    ),
    _Spec(
        "GNSS/live_gnss_qcom",
        f"{_LOG}/GNSS/live_gnss_qcom",
        TableName.GNSS,
        "ned",
        "live_gnss",
        "phone-chip fixes: lat, lon, speed, utc_ms, alt, bearing",
    ),
    _Spec(
        "CAN",
        f"{_LOG}/CAN/speed",
        TableName.VEHICLE,
        "frd",
        "speed+wheel_speed+steering",
        "CAN speed, wheel speeds and steering-wheel angle",
    ),
    _Spec("global_pose", "global_pose", TableName.TRUTH, "ned", "global_pose", CAMERA_POSE),
    _Spec("GNSS/raw_gnss_ublox", f"{_LOG}/GNSS/raw_gnss_ublox", None, None, "raw_gnss", ""),
    _Spec("GNSS/raw_gnss_qcom", f"{_LOG}/GNSS/raw_gnss_qcom", None, None, "raw_gnss", ""),
    _Spec(
        "IMU/magnetometer",
        f"{_LOG}/IMU/magnetometer",
        None,
        None,
        "magnetometer",
        "magnetic field, uT: no canonical table",
    ),
)
_TIME_FILE = {"global_pose": "frame_times"}


@dataclass(frozen=True)
class _Clock:
    """Boot clock -> the declared time base: ``t = boot + offset + interp(boot, rel)``."""

    base: TimeBase
    offset_ns: int = 0
    pairs_boot_ns: I64 | None = None
    pairs_rel_ns: F64 | None = None
    note: str = ""

    def to_ns(self, boot_s: npt.ArrayLike) -> I64:
        boot = np.rint(np.asarray(boot_s, dtype=np.float64) * NS_PER_S).astype(np.int64)
        if self.pairs_boot_ns is None or self.pairs_rel_ns is None:
            return boot + self.offset_ns
        b0 = int(self.pairs_boot_ns[0])
        rel = np.interp(
            (boot - b0).astype(np.float64), (self.pairs_boot_ns - b0), self.pairs_rel_ns
        )
        return boot + self.offset_ns + np.rint(rel).astype(np.int64)


class Comma2k19Reader(LogReader):
    """Reader of one comma2k19 segment directory (see the module docstring)."""

    format = Format.COMMA2K19

    def __init__(self, detected: Detected, ctx: ReadContext) -> None:
        super().__init__(detected, ctx)
        self.root = detected.path
        self._clock: _Clock | None = None
        self._arrays: dict[Path, tuple[F64, _npy.NpyHeader]] = {}
        self._reported: set[tuple[str, str]] = set()

    # ------------------------------------------------------------------------------ inventory
    def inventory(self) -> Inventory:
        clock = self.clock()
        streams = []
        for spec in _SPECS:
            t_path = self._t_path(spec)
            if not t_path.is_file():
                continue
            t, header = self._load(t_path)
            count = len(t)
            detail = spec.detail
            if spec.key == "CAN":
                count = len(self._can_times())
            elif spec.table is None and spec.key.startswith("GNSS/raw"):
                detail = f"{len(np.unique(t))} epochs; not converted (no ephemeris, see notes)"
            if header.rows != len(t):
                detail += f" ({header.rows - len(t)} rows missing)"
            streams.append(
                StreamInfo(
                    key=spec.key,
                    msgtype=spec.msgtype,
                    count=count,
                    start_ns=int(clock.to_ns(t[:1])[0]) if count else None,
                    end_ns=int(clock.to_ns(t[-1:])[0]) if count else None,
                    table=spec.table,
                    time_base=clock.base,
                    frame=spec.frame,
                    detail=detail,
                )
            )
        notes = [clock.note]
        if any(s.key.startswith("GNSS/raw_gnss") for s in streams):
            notes.append(
                f"gnss_obs: {NO_EPHEMERIS} (a broadcast navigation file for the recording day "
                "would be needed; combining one with these arrays is not supported)"
            )
        if any(s.key == "global_pose" for s in streams):
            notes.append(CAMERA_POSE)
        return Inventory(self.path, self.format, tuple(streams), tuple(notes), PLATFORM)

    def clock(self) -> _Clock:
        """The boot-clock pairing from ``global_pose`` (cached)."""
        if self._clock is None:
            self._clock = self._make_clock()
        return self._clock

    def _make_clock(self) -> _Clock:
        times = self.root / "global_pose" / "frame_times"
        gps = self.root / "global_pose" / "frame_gps_times"
        if not (times.is_file() and gps.is_file()):
            return _Clock(
                TimeBase.RECORDER,
                note="no global_pose/frame_gps_times: every stream "
                "stays on the device's boot clock (time base recorder)",
            )
        boot_s, _ = self._load(times)
        week_tow, _ = self._load(gps)
        n = min(len(boot_s), len(week_tow))
        ok = np.isfinite(boot_s[:n]) & np.isfinite(week_tow[:n]).all(axis=1)
        if ok.sum() < 2:
            raise CorruptLogError("global_pose has fewer than two usable time pairs", path=gps)
        boot_ns = np.rint(boot_s[:n][ok] * NS_PER_S).astype(np.int64)
        gps_ns = week_tow[:n][ok, 0].astype(np.int64) * SECONDS_PER_WEEK * NS_PER_S + np.rint(
            week_tow[:n][ok, 1] * NS_PER_S
        ).astype(np.int64)
        offset = gps_ns - boot_ns
        median = int(np.median(offset))
        rel = (offset - median).astype(np.float64)
        order = np.argsort(boot_ns)
        spread_us = float(rel.max() - rel.min()) * 1e-3
        week = int(week_tow[:n][ok, 0][0])
        tow_offset_s = (median - week * SECONDS_PER_WEEK * NS_PER_S) * 1e-9
        note = (
            f"boot clock -> GPS time from global_pose: GPS = boot + {tow_offset_s:.6f} s "
            f"(GPS week {week}), {int(ok.sum())} pairs, spread {spread_us:.3f} us"
        )
        return _Clock(TimeBase.GPS, median, boot_ns[order], rel[order], note)

    # ----------------------------------------------------------------------------------- read
    def read(self, selections: Sequence[Selection]) -> Iterator[Batch]:
        builders = {
            "IMU": self._imu,
            "GNSS/live_gnss_ublox": lambda: self._fix("GNSS/live_gnss_ublox"),
            "GNSS/live_gnss_qcom": lambda: self._fix("GNSS/live_gnss_qcom"),
            "CAN": self._can,
            "global_pose": self._pose,
        }
        for sel in selections:
            build = builders.get(sel.key)
            if build is None:
                continue
            batch = build()
            step = self.ctx.batch_rows
            for i in range(0, max(len(batch), 1), step):
                yield _slice(batch, i, i + step)

    def _imu(self) -> Batch:
        t, acc, offsets = self._pair(f"{_LOG}/IMU/accelerometer")
        tg, gyro, _ = self._pair(f"{_LOG}/IMU/gyro")
        counters = {}
        if not np.array_equal(t, tg):
            # Accelerometer and gyro rows pair by identical stamps; unpaired rows are dropped.
            common, ia, ig = np.intersect1d(t, tg, return_indices=True)
            counters["imu_samples_without_partner_dropped"] = len(t) + len(tg) - 2 * len(common)
            t, acc, offsets, gyro = common, acc[ia], offsets[ia], gyro[ig]
        cols: dict[str, np.ndarray] = {"t_ns": self.clock().to_ns(t)}
        for k, axis in enumerate("xyz"):
            cols[f"acc_{axis}_mps2"] = acc[:, k]
            cols[f"gyro_{axis}_radps"] = gyro[:, k]
        info = {
            "axes": "[forward, right, down] as recorded (FRD)",
            "gyro": "Android bias-corrected rate (IMU/gyro)",
        }
        return Batch("IMU", TableName.IMU, cols, offsets, counters=counters, info=info)

    def _fix(self, key: str) -> Batch:
        t, v, offsets = self._pair(f"{_LOG}/{key}")
        lat, lon, speed, utc_ms, alt, bearing = (v[:, k] for k in range(6))
        vel_n, vel_e = velocity_ned_from_course(speed, bearing)
        valid = np.isfinite(lat) & np.isfinite(lon) & ~((lat == 0) & (lon == 0))
        clock = self.clock()
        t_ns = clock.to_ns(t)
        cols: dict[str, np.ndarray] = {
            "t_ns": t_ns,
            "lat_deg": lat,
            "lon_deg": lon,
            "alt_m": alt,
            "vel_n_mps": vel_n,
            "vel_e_mps": vel_e,
            "fix_type": np.where(valid, FixType.FIX_3D, FixType.NO_FIX).astype(np.int8),
        }
        info = {
            "time": "arrival on the boot clock (as every processed_log stream)",
            "velocity": "speed and bearing -> north/east; vel_d not provided",
            "altitude": "ellipsoidal (WGS-84)",
        }
        if clock.base == TimeBase.GPS:
            epoch_ms = np.rint(np.where(np.isfinite(utc_ms), utc_ms, 0)).astype(np.int64)
            epoch = utc_to_gps_ns(epoch_ms * 1_000_000)
            cols["latency_s"] = np.where(np.isfinite(utc_ms), (t_ns - epoch) * 1e-9, np.nan)
            info["latency_s"] = "arrival - the receiver's own UTC epoch (leap seconds applied)"
        counters = {"no_fix": int((~valid).sum())} if (~valid).any() else {}
        return Batch(key, TableName.GNSS, cols, offsets, counters=counters, info=info)

    def _can_times(self) -> F64:
        t_speed = self._load(self.root / _LOG / "CAN/speed/t")[0]
        steer = self.root / _LOG / "CAN/steering_angle/t"
        t_steer = self._load(steer)[0] if steer.is_file() else np.empty(0)
        return np.union1d(t_speed, t_steer)

    def _can(self) -> Batch:
        t_v, speed, off_v = self._pair(f"{_LOG}/CAN/speed")
        wheel_dir = self.root / _LOG / "CAN/wheel_speed"
        steer_dir = self.root / _LOG / "CAN/steering_angle"
        t_w, wheels, _ = (
            self._pair(f"{_LOG}/CAN/wheel_speed")
            if wheel_dir.is_dir()
            else (t_v, np.full((len(t_v), 4), np.nan), off_v)
        )
        t_s, steer_deg, off_s = (
            self._pair(f"{_LOG}/CAN/steering_angle")
            if steer_dir.is_dir()
            else (np.empty(0), np.empty(0), np.empty(0, np.int64))
        )
        t = np.union1d(t_v, t_s)
        iv, is_ = np.searchsorted(t, t_v), np.searchsorted(t, t_s)
        n = len(t)
        has_v, has_s = np.zeros(n, bool), np.zeros(n, bool)
        has_v[iv], has_s[is_] = True, True
        speed_col, steer_wheel = np.full(n, np.nan), np.full(n, np.nan)
        speed_col[iv] = speed.reshape(len(t_v), -1)[:, 0]
        steer_wheel[is_] = -np.radians(steer_deg.reshape(-1))
        offsets = np.zeros(n, np.int64)
        offsets[is_], offsets[iv] = off_s, off_v
        cols: dict[str, np.ndarray] = {
            "t_ns": self.clock().to_ns(t),
            "speed_mps": speed_col,
            "steer_wheel_rad": steer_wheel,
        }
        nulls: dict[str, Bools] = {"speed_mps": ~has_v, "steer_wheel_rad": ~has_s}
        wheel_rows = np.searchsorted(t, t_w)
        for k, name in enumerate(("fl", "fr", "rl", "rr")):
            col = np.full(n, np.nan)
            col[wheel_rows] = wheels.reshape(len(t_w), -1)[:, k]
            cols[f"wheel_{name}_mps"] = col
            mask = np.ones(n, bool)
            mask[wheel_rows] = False
            nulls[f"wheel_{name}_mps"] = mask
        ratio = self.ctx.config.vehicle.steer_ratio if self.ctx.config is not None else None
        info = {
            "steering": "steering_angle is the steering-wheel angle in deg, positive "
            "counter-clockwise (left); steer_wheel_rad = -rad(steering_angle), positive right"
        }
        if ratio:
            cols["steer_rad"] = steer_wheel / ratio
            nulls["steer_rad"] = ~has_s
            info["steer_rad"] = f"steer_wheel_rad / steer_ratio {ratio} (dataset.yaml)"
        else:
            info["steer_rad"] = "null: set vehicle.steer_ratio in dataset.yaml to convert"
        counters = {
            "rows_with_speed": int(has_v.sum()),
            "rows_with_steering": int(has_s.sum()),
            "rows_with_both": int((has_v & has_s).sum()),
        }
        return Batch(
            "CAN", TableName.VEHICLE, cols, offsets, nulls=nulls, counters=counters, info=info
        )

    def _pose(self) -> Batch:
        t, pos, offsets = self._pair("global_pose", "frame_times", "frame_positions")
        vel = self._load(self.root / "global_pose/frame_velocities")[0]
        quat = self._load(self.root / "global_pose/frame_orientations")[0]
        n = min(len(t), len(vel), len(quat))
        t, pos, vel, quat, offsets = t[:n], pos[:n], vel[:n], quat[:n], offsets[:n]
        lat, lon, alt = geodetic_from_ecef(pos)
        c_ned = c_ned_ecef(lat, lon)
        v_ned = np.einsum("nij,nj->ni", c_ned, vel)
        roll, pitch, yaw = rpy_from_dcm(c_ned @ dcm_from_quat_wxyz(quat))
        cols = {
            "t_ns": self.clock().to_ns(t),
            "lat_deg": lat,
            "lon_deg": lon,
            "alt_m": alt,
            "vel_n_mps": v_ned[:, 0],
            "vel_e_mps": v_ned[:, 1],
            "vel_d_mps": v_ned[:, 2],
            "roll_rad": roll,
            "pitch_rad": pitch,
            "yaw_rad": yaw,
        }
        return Batch("global_pose", TableName.TRUTH, cols, offsets, info={"truth": CAMERA_POSE})

    # -------------------------------------------------------------------------------- helpers
    def _t_path(self, spec: _Spec) -> Path:
        return self.root / spec.folder / _TIME_FILE.get(spec.key, "t")

    def _load(self, path: Path) -> tuple[F64, _npy.NpyHeader]:
        """An array of the segment, loaded once (its defects are recorded once)."""
        if path not in self._arrays:
            if not path.is_file():
                raise CorruptLogError("file missing from the segment", path=path)
            name = path.relative_to(self.root).as_posix()
            self._arrays[path] = _npy.load(path, self.damage, name)
        return self._arrays[path]

    def _pair(self, folder: str, t_name: str = "t", v_name: str = "value") -> tuple[F64, F64, I64]:
        """Times, values and row offsets of one stream; rows cut to the shorter file.

        Files that declare different row counts are inconsistent (recorded); a file cut short
        is already recorded as truncated by ``_npy.load``.
        """
        t, th = self._load(self.root / folder / t_name)
        v, vh = self._load(self.root / folder / v_name)
        n = min(len(t), len(v))
        if th.rows != vh.rows and (folder, "pair") not in self._reported:
            self._reported.add((folder, "pair"))
            self.damage.record(
                Defect(
                    Completeness.BAD_DATA_SKIPPED,
                    f"{folder}: {t_name} declares {th.rows} rows, {v_name} {vh.rows}: "
                    f"rows paired by index and cut to {n}",
                    offset=th.data_offset + n * th.row_bytes,
                    messages_lost=abs(th.rows - vh.rows),
                )
            )
        return t[:n], v[:n], th.row_offsets(n)


def _slice(batch: Batch, start: int, stop: int) -> Batch:
    if start == 0 and stop >= len(batch):
        return batch
    return Batch(
        batch.key,
        batch.table,
        {k: v[start:stop] for k, v in batch.columns.items()},
        batch.offsets[start:stop],
        {k: v[start:stop] for k, v in batch.nulls.items()},
        batch.frame,
        batch.counters if start == 0 else {},
        batch.info,
    )
