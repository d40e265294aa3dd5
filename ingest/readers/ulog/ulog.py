"""PX4 ULog (``.ulg``) through pyulog, which already decodes each topic into column arrays.

Streams (``topic[multi_id]``), all on the boot clock ``timestamp`` (us) until paired:

=============================  ============================================================
sensor_combined[i]             ``gyro_rad[0..2]`` rad/s, ``accelerometer_m_s2[0..2]`` m/s^2,
                               body FRD -> imu
sensor_accel[i]                ``x/y/z`` m/s^2 with ``sensor_gyro[i]`` ``x/y/z`` rad/s nearest
 + sensor_gyro[i]              in time -> imu, only in a log without sensor_combined
vehicle_gps_position[i],       ``lat/lon`` 1e-7 deg (or ``latitude_deg``...), ``alt`` mm MSL,
sensor_gps[i]                  ``alt_ellipsoid`` mm, ``eph/epv`` m (PX4's accuracies),
                               ``s_variance_m_s`` m/s, ``vel_n/e/d_m_s``, ``fix_type``,
                               ``satellites_used`` -> gnss
vehicle_global_position[i]     ``lat/lon`` deg, ``alt`` m MSL (``alt_ellipsoid`` when logged),
 + vehicle_attitude            ``vel_n/e/d`` when logged; attitude from the quaternion ``q``
                               (Hamilton, body FRD -> NED) nearest in time -> estimator
vehicle_local_position[i]      ``x/y/z``, ``vx/vy/vz`` NED from ``ref_lat/ref_lon/ref_alt``
 + vehicle_attitude            (PX4's azimuthal-equidistant projection, valid where
                               ``xy_global``/``z_global``; NaN otherwise) -> estimator
vehicle_global_position_       the simulator's state (PX4 SITL), as vehicle_global_position
groundtruth[i] + vehicle_      (heights MSL unless ``alt_ellipsoid`` is logged: the GPS
attitude_groundtruth           heights of SITL are MSL too) -> truth
=============================  ============================================================

Time: when a GPS topic carries ``time_utc_usec``, the boot clock is paired with it (median of
``time_utc_usec - timestamp`` over the fixes), converted to GPS time with the leap-second table
and declared GPS; otherwise the boot clock stays the recorder clock.

Damage: pyulog stops at a message cut by the end of the file and resynchronises on sync
markers after corrupt bytes, silently; this reader walks the message headers itself to report
a trailing partial message with its offset, reports pyulog's corruption flag, and counts the
logger's own dropouts. pyulog loads the file whole (ULog files are seldom above a few hundred
MB); unreadable headers are E-FATAL naming the file.
"""

from __future__ import annotations

import contextlib
import io
import logging
import struct
from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np

from navreplay.ingest.arrays import I64
from navreplay.ingest.context import LogContext, changes, forward, px4_mode_name
from navreplay.ingest.damage import Completeness, Defect
from navreplay.ingest.detect import Detected, Format
from navreplay.ingest.errors import CorruptLogError
from navreplay.ingest.platform import UNKNOWN, Platform, from_mav_type, from_px4_status
from navreplay.ingest.readers.asof import AsofJoin, Left
from navreplay.ingest.readers.base import (
    Batch,
    Inventory,
    LogReader,
    ReadContext,
    Selection,
    StreamInfo,
)
from navreplay.ingest.readers.ulog.ulogmsgs import (
    GPS_TOPICS,
    TOPICS,
    UlogTopic,
    attitude_columns,
    gyro_columns,
)
from navreplay.ingest.schema import (
    ESTIMATOR_INNOVATIONS,
    ESTIMATOR_TEST_RATIOS,
    EventKind,
    TableName,
)
from navreplay.ingest.timebase import TimeBase, utc_to_gps_ns

log = logging.getLogger(__name__)

JOIN_TOLERANCE_NS = 50_000_000
_STATUS = "vehicle_status"
_EKF_STATUS = "estimator_status"  # the onboard EKF's test ratios (joined to its estimate)
_IMU_STATUS = "vehicle_imu_status"  # vibration and clipping per IMU (PX4 1.11 on)
# the onboard EKF's innovations, joined to its estimate (ekf2_innovations until PX4 1.10)
_INNOVATIONS = ("estimator_innovations", "ekf2_innovations")
_AUXILIARY = (_STATUS, _EKF_STATUS, _IMU_STATUS, *_INNOVATIONS)  # platform, ratios, context
_STATUS_FIELDS = ("system_type", "is_vtol", "is_rotary_wing", "vehicle_type")
_HEADER = 16
_ARMED = 2  # vehicle_status.arming_state ARMING_STATE_ARMED
#: estimator_innovations fields of ESTIMATOR_INNOVATIONS, PX4 1.9 and then 1.11 on
_INNOVATION_FIELDS = (
    tuple(f"vel_pos_innov[{i}]" for i in range(6)),
    ("gps_hvel[0]", "gps_hvel[1]", "gps_vvel", "gps_hpos[0]", "gps_hpos[1]", "gps_vpos"),
)
_CLIPPING = ("accel_clipping[0]", "accel_clipping[1]", "accel_clipping[2]")


class UlogReader(LogReader):
    """Reader of one PX4 ULog file."""

    format = Format.ULOG

    def __init__(self, detected: Detected, ctx: ReadContext) -> None:
        super().__init__(detected, ctx)
        self._ulog: Any = None
        self._offset_ns: int | None = None
        self._pairs = 0

    def _load(self) -> Any:
        if self._ulog is not None:
            return self._ulog
        from pyulog import ULog
        from pyulog.core import ULogException

        names = [*(t.name for t in TOPICS), *{t.attitude or t.pair for t in TOPICS} - {""}]
        names += list(_AUXILIARY)
        printed = io.StringIO()
        try:
            with contextlib.redirect_stdout(printed):  # pyulog prints its warnings
                self._ulog = ULog(str(self.file), names, True)
        except (ULogException, struct.error, ValueError, IndexError, OSError) as err:
            raise CorruptLogError(
                f"ULog cannot be parsed: {err}", path=self.file, offset=0
            ) from err
        finally:
            for line in printed.getvalue().splitlines():
                log.info("%s: pyulog: %s", self.file, line)
        if not [d for d in self._ulog.data_list if d.name not in _AUXILIARY]:
            corrupt = " and reports the file corrupt" if self._ulog.file_corruption else ""
            raise CorruptLogError(
                f"pyulog finds no data message of the topics navreplay converts{corrupt}",
                path=self.file,
                offset=_HEADER,
                hint=f"topics read: {', '.join(names)}",
            )
        self._pair_clock()
        return self._ulog

    def _pair_clock(self) -> None:
        diffs: list[I64] = []
        for d in self._ulog.data_list:
            if d.name in GPS_TOPICS and "time_utc_usec" in d.data:
                utc = d.data["time_utc_usec"].astype(np.int64)
                ok = utc > 0
                diffs.append((utc[ok] - d.data["timestamp"].astype(np.int64)[ok]) * 1000)
        both = np.concatenate(diffs) if diffs else np.empty(0, np.int64)
        if len(both):
            self._offset_ns = int(np.sort(both)[len(both) // 2])
            self._pairs = len(both)

    @property
    def base(self) -> TimeBase:
        self._load()
        return TimeBase.GPS if self._offset_ns is not None else TimeBase.RECORDER

    def to_base(self, timestamp_us: np.ndarray) -> I64:
        t = np.asarray(timestamp_us, dtype=np.int64) * 1000
        if self._offset_ns is None:
            return t
        return utc_to_gps_ns(t + self._offset_ns)

    # ----------------------------------------------------------------------------- inventory
    def _datasets(self) -> Iterator[tuple[UlogTopic, Any]]:
        by_name = {t.name: t for t in TOPICS}
        present = {d.name for d in self._load().data_list if len(d.data["timestamp"])}
        for d in sorted(self._load().data_list, key=lambda d: (d.name, d.multi_id)):
            topic = by_name.get(d.name)
            if topic is None or not len(d.data["timestamp"]):
                continue
            if topic.fallback_for in present or (topic.pair and topic.pair not in present):
                continue
            yield topic, d

    def inventory(self) -> Inventory:
        streams = []
        for topic, d in self._datasets():
            ts = d.data["timestamp"]
            first, last = self.to_base(np.array([ts[0], ts[-1]]))
            refused = (
                _imu_coverage(d.name, d.multi_id, d.data) if topic.table == TableName.IMU else ""
            )
            streams.append(
                StreamInfo(
                    key=f"{d.name}[{d.multi_id}]",
                    msgtype=d.name,
                    count=len(ts),
                    start_ns=int(first),
                    end_ns=int(last),
                    table=None if refused else topic.table,
                    time_base=self.base,
                    frame="frd" if topic.table in (TableName.IMU, TableName.MAG) else "ned",
                    instance=int(d.multi_id),
                    detail=f"not usable as imu: {refused}" if refused else topic.detail,
                    refused=refused,
                )
            )
        platform = self._platform()
        notes = (self._time_note(), f"platform: {platform.text()}")
        return Inventory(self.path, self.format, tuple(streams), notes, platform)

    def _platform(self) -> Platform:
        """From the first ``vehicle_status`` (fields by version), else the MAV_TYPE parameter."""
        for d in self._load().data_list:
            if d.name == _STATUS and len(d.data["timestamp"]):
                fields = {k: int(d.data[k][0]) for k in _STATUS_FIELDS if k in d.data}
                found = from_px4_status(fields)
                if found.known:
                    return found
        value = self._load().initial_parameters.get("MAV_TYPE")
        if value is not None:
            return from_mav_type(int(value), "parameter MAV_TYPE") or UNKNOWN
        return UNKNOWN

    def _time_note(self) -> str:
        if self._offset_ns is None:
            return "no GPS UTC time in the log: timestamp (time since boot) kept as recorder clock"
        return (
            f"timestamp paired with GPS time_utc_usec ({self._pairs} fixes, UTC - boot = "
            f"{self._offset_ns / 1e9:.6f} s), converted to GPS time"
        )

    # ---------------------------------------------------------------------------------- read
    def read(self, selections: Sequence[Selection]) -> Iterator[Batch]:
        keys = {s.key for s in selections}
        ulog = self._load()
        extras = self._undulation()
        for topic, d in self._datasets():
            key = f"{d.name}[{d.multi_id}]"
            if key not in keys:
                continue
            try:
                conv = topic.convert(d.data, extras)
            except KeyError as err:
                raise CorruptLogError(
                    f"topic {d.name} lacks field {err} in the log's definition of it",
                    path=self.file,
                    record=f"topic {key}",
                    hint="a damaged format definition (ULog has no checksums) or a PX4 "
                    "version whose topic layout navreplay does not know; select another "
                    "topic in dataset.yaml",
                ) from err
            t = self.to_base(d.data["timestamp"])
            offsets = np.zeros(len(t), np.int64)  # pyulog does not expose record offsets
            if topic.attitude:
                yield self._with_attitude(key, topic, t, conv, offsets, ulog)
                continue
            if topic.pair:
                yield self._with_pair(key, topic, d.multi_id, t, conv, offsets, ulog)
                continue
            cols = {"t_ns": t, **conv.columns}
            yield Batch(key, topic.table, cols, offsets, conv.nulls, None, conv.counters, conv.info)
        self._record_damage(ulog)

    # ------------------------------------------------------------------------------- context
    def context(self) -> LogContext:
        """``logged_messages`` (their log level as severity), ``vehicle_status`` mode
        (``nav_state``) and arming changes, and vibration: ``vehicle_imu_status`` per IMU
        (``accel_vibration_metric`` m/s^2, ``gyro_vibration_metric`` rad/s, the clipping
        counts of its three axes summed) or, in older logs, ``estimator_status.vibe``
        (high-frequency delta-angle and delta-velocity vibration, rad and m/s)."""
        ulog = self._load()
        out = LogContext(self.base)
        msgs = ulog.logged_messages
        if msgs:
            t = self.to_base(np.array([m.timestamp for m in msgs], np.int64))
            levels = [m.log_level - ord("0") for m in msgs]
            severity = [lv if 0 <= lv <= 7 else None for lv in levels]
            texts = [str(m.message) for m in msgs]
            out.events.add(t, EventKind.MESSAGE, texts, "logged_messages", severity)
        for d in ulog.data_list:
            if d.name == _STATUS and d.multi_id == 0 and len(d.data["timestamp"]):
                self._status_events(out, d.data)
        out.vibration = self._vibration(ulog)
        return out

    def _status_events(self, out: LogContext, data: dict[str, np.ndarray]) -> None:
        ahead = forward(data["timestamp"])
        data = {k: v[ahead] for k, v in data.items()}
        t = self.to_base(data["timestamp"])
        if "nav_state" in data:
            nav = data["nav_state"].astype(int)
            at = changes(nav)
            modes = [px4_mode_name(int(nav[i])) for i in at]
            out.events.add(t[at], EventKind.MODE, modes, _STATUS)
        if "arming_state" in data:
            armed = data["arming_state"].astype(int) == _ARMED
            at = changes(armed)
            states = ["armed" if armed[i] else "disarmed" for i in at]
            out.events.add(t[at], EventKind.ARMING, states, _STATUS)

    def _vibration(self, ulog: Any) -> dict[str, np.ndarray]:
        parts: list[dict[str, np.ndarray]] = []
        for d in ulog.data_list:
            data, n = d.data, len(d.data["timestamp"])
            if d.name == _IMU_STATUS and n and "accel_vibration_metric" in data:
                clips = [data[f] for f in _CLIPPING if f in data]
                gyro = data.get("gyro_vibration_metric", np.full(n, np.nan))
                clip = np.sum(np.array(clips, np.float64), axis=0) if clips else np.full(n, np.nan)
                parts.append({
                    "t_ns": self.to_base(data["timestamp"]),
                    "imu": np.full(n, d.multi_id, np.int64),
                    "accel_vibe_mps2": np.asarray(data["accel_vibration_metric"], np.float64),
                    "gyro_vibe_radps": np.asarray(gyro, np.float64),
                    "clip_count": clip,
                })  # fmt: skip
        if parts:
            return {k: np.concatenate([p[k] for p in parts]) for k in parts[0]}
        for d in ulog.data_list:
            data, n = d.data, len(d.data["timestamp"])
            if d.name == _EKF_STATUS and d.multi_id == 0 and n and "vibe[2]" in data:
                return {
                    "t_ns": self.to_base(data["timestamp"]),
                    "imu": np.zeros(n, np.int64),
                    "dang_vibe_rad": data["vibe[1]"].astype(np.float64),
                    "dvel_vibe_mps": data["vibe[2]"].astype(np.float64),
                }
        return {}

    def _undulation(self) -> float | None:
        for d in self._ulog.data_list:
            if d.name in GPS_TOPICS and "alt_ellipsoid" in d.data and "alt" in d.data:
                diff = d.data["alt_ellipsoid"].astype(np.int64) - d.data["alt"].astype(np.int64)
                diff = diff[d.data["alt_ellipsoid"] != 0]
                if len(diff):
                    return float(np.median(diff)) / 1000.0
        return None

    def _with_pair(
        self, key: str, topic: UlogTopic, multi_id: int, t: I64, conv: Any, offsets: I64, ulog: Any
    ) -> Batch:
        """``sensor_accel`` rows with the ``sensor_gyro`` of the same instance nearest in time
        (null beyond ``JOIN_TOLERANCE_NS``, counted)."""
        join = AsofJoin(("gyro_x_radps", "gyro_y_radps", "gyro_z_radps"), JOIN_TOLERANCE_NS)
        for d in ulog.data_list:
            if d.name == topic.pair and d.multi_id == multi_id:
                join.push_right(self.to_base(d.data["timestamp"]), gyro_columns(d.data))
        join.push_left(Left(t, conv.columns, conv.nulls, offsets))
        out = join.pop(final=True)
        assert out is not None
        counters = dict(conv.counters)
        missing = int(out.nulls["gyro_x_radps"].sum()) if "gyro_x_radps" in out.nulls else 0
        if missing:
            counters["gyro_not_within_50ms"] = missing
        cols = {"t_ns": out.t, **out.columns}
        return Batch(key, topic.table, cols, out.offsets, out.nulls, None, counters, conv.info)

    def _with_attitude(
        self, key: str, topic: UlogTopic, t: I64, conv: Any, offsets: I64, ulog: Any
    ) -> Batch:
        join = AsofJoin(("roll_rad", "pitch_rad", "yaw_rad"), JOIN_TOLERANCE_NS)
        for d in ulog.data_list:
            if d.name == topic.attitude and d.multi_id == 0:
                join.push_right(self.to_base(d.data["timestamp"]), attitude_columns(d.data))
        join.push_left(Left(t, conv.columns, conv.nulls, offsets))
        out = join.pop(final=True)
        assert out is not None
        info = {**conv.info, "attitude": f"{topic.attitude}[0] q, nearest in time"}
        if topic.table == TableName.ESTIMATOR:
            out = self._with_test_ratios(out, ulog)
            out = self._with_innovations(out, ulog)
        cols = {"t_ns": out.t, **out.columns}
        return Batch(key, topic.table, cols, out.offsets, out.nulls, None, conv.counters, info)

    def _with_test_ratios(self, rows: Left, ulog: Any) -> Left:
        """The onboard EKF's test ratios (``estimator_status[0]``, nearest in time) joined to
        its estimate, where the log has them."""
        fields = [f.replace("test_ratio_", "") + "_test_ratio" for f in ESTIMATOR_TEST_RATIOS]
        status = [d for d in ulog.data_list if d.name == _EKF_STATUS and d.multi_id == 0]
        if not status or not all(f in status[0].data for f in fields):
            return rows
        d = status[0]
        join = AsofJoin(ESTIMATOR_TEST_RATIOS, JOIN_TOLERANCE_NS)
        columns = {
            name: np.asarray(d.data[f], dtype=np.float64)
            for name, f in zip(ESTIMATOR_TEST_RATIOS, fields, strict=True)
        }
        join.push_right(self.to_base(d.data["timestamp"]), columns)
        join.push_left(rows)
        out = join.pop(final=True)
        assert out is not None
        return out

    def _with_innovations(self, rows: Left, ulog: Any) -> Left:
        """The onboard EKF's GNSS velocity and position innovations (``ekf2_innovations``
        ``vel_pos_innov[0..5]`` until PX4 1.10, ``estimator_innovations`` ``gps_hvel``/
        ``gps_vvel``/``gps_hpos``/``gps_vpos`` after), nearest in time, where logged."""
        found = [d for d in ulog.data_list if d.name in _INNOVATIONS and d.multi_id == 0]
        if not found:
            return rows
        data = found[0].data
        for fields in _INNOVATION_FIELDS:
            if all(f in data for f in fields):
                break
        else:
            return rows
        join = AsofJoin(ESTIMATOR_INNOVATIONS, JOIN_TOLERANCE_NS)
        columns = {
            name: np.asarray(data[f], dtype=np.float64)
            for name, f in zip(ESTIMATOR_INNOVATIONS, fields, strict=True)
        }
        join.push_right(self.to_base(data["timestamp"]), columns)
        join.push_left(rows)
        out = join.pop(final=True)
        assert out is not None
        return out

    # -------------------------------------------------------------------------------- damage
    def _record_damage(self, ulog: Any) -> None:
        self.damage.note(self._time_note())
        drops = list(ulog.dropouts)
        if drops:
            self.damage.count("logger_dropouts", len(drops))
            total = sum(int(x.duration) for x in drops)
            self.damage.note(f"{len(drops)} logger dropouts (buffer overruns), {total} ms in all")
        if ulog.file_corruption:
            self.damage.record(
                Defect(
                    Completeness.CORRUPT_CHUNKS_SKIPPED,
                    "pyulog detected corrupt bytes and resynchronised on the next sync marker: "
                    "the messages in between are lost (count unknown)",
                )
            )
        partial = _trailing_partial(self.file)
        if partial is not None:
            at, n = partial
            self.damage.record(
                Defect(
                    Completeness.PARTIAL_RECORD_DROPPED,
                    f"1 trailing partial message dropped at offset {at} ({n} bytes): the file "
                    "ends inside it",
                    offset=at,
                    messages_lost=1,
                    bytes_skipped=n,
                )
            )


#: Below this share of the log's time covered by its IMU samples' integration intervals, the
#: samples are snapshots of a vibrating vehicle, not its motion: an INS cannot integrate them.
MIN_IMU_COVERAGE = 0.5


def _imu_coverage(name: str, multi_id: int, data: Any) -> str:
    """Why ``sensor_combined`` cannot feed the IMU table, or "": each sample is the rate and
    specific force integrated over ``*_integral_dt`` (us; seconds as float in PX4 < 1.7); a
    logging profile that keeps one sample in 32 leaves most of the motion unmeasured."""
    ts = np.asarray(data["timestamp"], np.int64)
    dt_name = "accelerometer_integral_dt"
    if dt_name not in data or len(ts) < 2 or ts[-1] <= ts[0]:
        return ""
    dt = np.asarray(data[dt_name], np.float64)
    dt_us = dt * 1e6 if float(np.median(dt)) < 1.0 else dt
    span_us = float(ts[-1] - ts[0])
    share = float(dt_us.sum()) / span_us
    if share >= MIN_IMU_COVERAGE:
        return ""
    rate = (len(ts) - 1) / (span_us * 1e-6)
    return (
        f"{name}[{multi_id}] has {len(ts)} samples over {span_us * 1e-6:.1f} s ({rate:.1f} Hz), "
        f"each integrating {float(np.median(dt_us)) / 1000:.1f} ms ({dt_name}): only "
        f"{100 * share:.1f} % of the time is measured, the rest of the motion is not in the log "
        "(a reduced logging profile, SDLOG_PROFILE); an INS cannot integrate it. Log "
        "sensor_combined at full rate (PX4 logs it at its rate with the default profile)"
    )


def _trailing_partial(path: Any) -> tuple[int, int] | None:
    """(offset, bytes) of a message cut by the end of the file, by walking the headers."""
    data = np.fromfile(path, np.uint8)
    size = len(data)
    pos = _HEADER
    while pos + 3 <= size:
        msg_size = int(data[pos]) | (int(data[pos + 1]) << 8)
        if pos + 3 + msg_size > size:
            return pos, size - pos
        pos += 3 + msg_size
    return (pos, size - pos) if pos < size else None
