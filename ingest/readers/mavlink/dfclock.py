"""The survey pass over a DataFlash log: streams, boot segments, and TimeUS -> GPS time.

``survey(path)`` scans the log once and learns:

- message counts per stream and instance, first/last TimeUS;
- boot segments from TimeUS of every record that starts with it (``BootTracker``: a drop by
  more than 10 s is a reboot, catalogue case 37);
- per segment, ``GPS - boot``: the median over GPS records with a 2-D fix or better of
  ``GWk * 604800 s + GMS - TimeUS`` (ArduPilot stamps a GPS record with the boot time of the
  fix, so the spread is sub-millisecond on real logs);
- GPS week rollover (case 35): the first GPS time is compared with a reference date
  (``utc_date`` in dataset.yaml, else the file's modification time: a DataFlash log has no
  other clock) and moved by multiples of 1024 weeks to the epoch nearest it;
- the EKF origins (``ORGN`` type 0) and the geoid undulation (median ``GPA.Und``); a
  2014-2015 log's ``EKF1`` has no ``ORGN``: its origin is estimated from the 3-D fixes
  (``DfSurvey._estimated_origin``) and the estimator rows counted as such.

The file's base is GPS when every boot segment is paired, else the recorder clock (TimeUS).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import numpy.typing as npt

from navreplay.ingest.arrays import I64
from navreplay.ingest.readers.mavlink.dfformat import FMT_TYPE, DfFormat
from navreplay.ingest.readers.mavlink.dfmsgs import (
    BY_MESSAGE,
    BY_NAME,
    LOCATION_SCALING_FACTOR_INV,
    PX4_BY_MESSAGE,
    PX4_BY_NAME,
    DfExtras,
    DfStream,
    Origin,
)
from navreplay.ingest.readers.mavlink.dfscan import (
    Formats,
    Records,
    ScanStats,
    Unusable,
    scan_blocks,
)
from navreplay.ingest.readers.mavlink.mavclock import (
    BootTracker,
    OffsetAccumulator,
    unroll_gps_week,
)
from navreplay.ingest.schema import FixType
from navreplay.ingest.timebase import NS_PER_S, SECONDS_PER_WEEK, TimeBase, utc_to_gps_ns

WEEK_NS = SECONDS_PER_WEEK * NS_PER_S


def instances(fixed: int, fmt: DfFormat, rec: Records, idx: npt.NDArray[np.intp]) -> I64:
    """Instance of records ``idx``: their ``I``/``C`` column, else ``fixed`` (legacy
    ``IMU2``); read without decoding the records."""
    col = fmt.instance_column
    if col is None:
        return np.full(len(idx), fixed, dtype=np.int64)
    return np.asarray(rec.column(idx, fmt, col), dtype=np.int64)


@dataclass
class RecordClock:
    """Boot time (us) of every record, block after block in file order: the record's own
    clock column (``DfFormat.boot_clock``: ``TimeUS``, ``TimeMS``, GPS ``T``, PX4 ``TIME``)
    or, for a record without one, that of the timed record before it (legacy PX4 logs time
    a whole frame of records by one ``TIME`` record; old ArduPilot GPS records without
    ``T``), the first timed record's for records before any."""

    held: int | None = None

    def times(self, formats: Formats, rec: Records) -> tuple[I64, npt.NDArray[np.bool_]]:
        """(boot us of every record of ``rec``, mask of the records with their own clock)."""
        out = np.zeros(len(rec), np.int64)
        has = np.zeros(len(rec), bool)
        for type_ in rec.types():
            idx_all = rec.of_type(type_)
            for fmt, sub in formats.split(type_, rec.offset[idx_all]):
                clock = fmt.boot_clock if fmt is not None else None
                if fmt is None or clock is None:
                    continue
                idx = idx_all[sub]
                col, per = clock
                out[idx] = np.asarray(rec.column(idx, fmt, col), np.int64) * per
                has[idx] = True
        timed = np.flatnonzero(has)
        if len(timed) < len(rec):
            if len(timed):
                j = np.searchsorted(timed, np.arange(len(rec)), side="right") - 1
                before = self.held if self.held is not None else int(out[timed[0]])
                out = np.where(j >= 0, out[timed[np.maximum(j, 0)]], before)
            elif self.held is not None:
                out[:] = self.held
        if len(timed):
            self.held = int(out[timed[-1]])
        return out, has


@dataclass
class DfSurvey:
    """What the survey learns (see the module docstring)."""

    formats: Formats = field(default_factory=Formats)
    stats: ScanStats = field(default_factory=ScanStats)
    tracker: BootTracker = field(default_factory=BootTracker)
    counts: Counter[tuple[str, int]] = field(default_factory=Counter)
    first_us: dict[tuple[str, int], int] = field(default_factory=dict)
    last_us: dict[tuple[str, int], int] = field(default_factory=dict)
    instanced: dict[str, bool] = field(default_factory=dict)
    unusable_detail: dict[str, str] = field(default_factory=dict)
    pairs: OffsetAccumulator = field(default_factory=OffsetAccumulator)
    undulation_mm: OffsetAccumulator = field(default_factory=OffsetAccumulator)
    origins: list[tuple[int, float, float, float]] = field(default_factory=list)
    platform: list[str] = field(default_factory=list)  # firmware and board, from MSG/VER
    q_enable: float | None = None  # ArduPlane's Q_ENABLE parameter (a QuadPlane when set)
    fixes: list[np.ndarray] = field(default_factory=list)  # (boot us, lat, lon, MSL alt) rows
    ekf1: list[np.ndarray] = field(default_factory=list)  # (boot us, PN, PE, PD) rows
    gps_first: tuple[int, int] | None = None
    gps_rows: int = 0
    data_records: int = 0
    timed_records: int = 0
    per_type: Counter[int] = field(default_factory=Counter)
    week_shift: int = 0
    last_gpstime: int = -1
    reference: str = ""
    offsets_ns: list[int | None] = field(default_factory=list)
    base: TimeBase = TimeBase.RECORDER
    clock: RecordClock = field(default_factory=RecordClock)

    @property
    def px4(self) -> bool:
        """A legacy PX4 (sdlog2) log: a ``TIME`` message with ``StartTime``."""
        return any(
            (f := self.formats.current.get(t)) is not None and f.boot_clock == ("StartTime", 1)
            for t in self.formats.types_seen("TIME")
        )

    @property
    def specs(self) -> dict[str, DfStream]:
        """The streams that feed tables, by stream name, for this log's flavour."""
        return PX4_BY_NAME if self.px4 else BY_NAME

    @property
    def by_message(self) -> dict[str, tuple[DfStream, ...]]:
        """The streams that feed tables, by the message they are read from."""
        return PX4_BY_MESSAGE if self.px4 else BY_MESSAGE

    @property
    def clock_name(self) -> str:
        """The log's boot clock in its own terms."""
        if self.px4:
            return "TIME.StartTime"
        names = {f.boot_clock[0] for f in self.formats.current.values() if f.boot_clock is not None}
        return "TimeMS" if "TimeMS" in names else "TimeUS"

    @property
    def unusable(self) -> list[Unusable]:
        return list(self.formats.unusable.values())

    def extras(self) -> DfExtras:
        und = self.undulation_mm.median(0)
        o = sorted(self.origins)
        origin = Origin(
            np.array([x[0] for x in o], np.int64),
            np.array([x[1] for x in o]),
            np.array([x[2] for x in o]),
            np.array([x[3] for x in o]),
        )
        estimated = False
        if not o:
            found = self._estimated_origin()
            if found is not None:
                origin, estimated = found, True
        return DfExtras(None if und is None else -und * 1e-3, origin, estimated)

    def _estimated_origin(self) -> Origin | None:
        """The origin of a pre-2016 EKF1 (NavEKF logged no ``ORGN``): the median over the 3-D
        fixes of the fix minus the EKF's position offset at the fix time, inverting
        ArduPilot's flat-earth ``Location::offset``."""
        if not self.fixes or not self.ekf1:
            return None
        fix, ekf = np.concatenate(self.fixes), np.concatenate(self.ekf1)
        ekf = ekf[np.argsort(ekf[:, 0], kind="stable")]
        inside = (fix[:, 0] >= ekf[0, 0]) & (fix[:, 0] <= ekf[-1, 0])
        fix = fix[inside]
        if len(fix) < 10:
            return None
        pn, pe, pd = (np.interp(fix[:, 0], ekf[:, 0], ekf[:, j]) for j in (1, 2, 3))
        lat = fix[:, 1] - pn * LOCATION_SCALING_FACTOR_INV * 1e-7
        scale = np.maximum(
            np.cos(np.radians(fix[:, 1] - pn * LOCATION_SCALING_FACTOR_INV * 5e-8)), 0.01
        )
        lon = fix[:, 2] - pe * LOCATION_SCALING_FACTOR_INV * 1e-7 / scale
        alt = fix[:, 3] + pd
        return Origin(
            np.zeros(1, np.int64),
            np.array([np.median(lat)]),
            np.array([np.median(lon)]),
            np.array([np.median(alt)]),
        )

    def to_base(self, time_us: I64, offsets: I64) -> I64:
        """``t_ns`` of records with ``time_us`` at file ``offsets``, on the file's base."""
        t = np.asarray(time_us, np.int64) * 1000
        if self.base == TimeBase.RECORDER:
            return t
        segs = self.tracker.segment_of(np.asarray(offsets, np.int64))
        return t + np.array([o or 0 for o in self.offsets_ns], np.int64)[segs]

    def fix_times(self, data: np.ndarray, fmt: DfFormat, t: I64) -> I64:
        """GPS fixes at their own epoch (GWk/GMS, rollover undone) where the receiver gave one."""
        if self.base != TimeBase.GPS or fmt.gps_time is None or len(fmt.gps_time) == 1:
            return t  # legacy PX4 GPSTime is the last whole UTC second: the log time is closer
        epoch, given = gps_epochs(data, fmt)
        return np.where(given, epoch + self.week_shift * WEEK_NS, t)

    def other_messages(self) -> dict[str, int]:
        """Record counts of the message types that feed no table, by name."""
        out: dict[str, int] = {}
        for type_, n in sorted(self.per_type.items()):
            fmt = self.formats.current.get(type_)
            name = fmt.name if fmt is not None else f"type {type_}"
            if name not in self.by_message:
                out[name] = out.get(name, 0) + n
        return out

    def time_note(self) -> str:
        clock = self.clock_name
        if self.base == TimeBase.RECORDER:
            why = self._why_no_gps_time()
            return (
                f"no GPS time in the log ({why}): {clock} (time since boot) kept as the "
                "recorder clock"
            )
        offs = ", ".join(f"{o / 1e9:.6f} s" for o in self.offsets_ns if o is not None)
        gps = "GPSTime (UTC)" if self.px4 else "GPS week/ms"
        return (
            f"{clock} paired with {gps} per boot segment (GPS - boot = {offs}, from "
            f"{sum(self.pairs.count(i) for i in range(len(self.offsets_ns)))} GPS records)"
        )

    def _why_no_gps_time(self) -> str:
        gps = sum(n for (name, _), n in self.counts.items() if name in ("GPS", "GPS2"))
        if not gps:
            return "no GPS record"
        if not self.gps_rows:
            return f"{gps} GPS records, none with a GPS week and time"
        paired = sum(self.pairs.count(i) for i in range(len(self.offsets_ns)))
        if not paired:
            return f"{gps} GPS records, none with a 2-D fix or better"
        missing = [i for i, o in enumerate(self.offsets_ns) if o is None]
        return f"boot segments {missing} have no GPS record with a fix"


def survey(path: Path, utc_date: str | None = None) -> DfSurvey:
    """One scan of ``path`` (see the module docstring); ``utc_date`` (``YYYY-MM-DD``, from
    dataset.yaml) is the rollover reference when given, else the file's modification time."""
    s = DfSurvey()
    for rec in scan_blocks(path, s.formats, s.stats):
        _block(s, rec)
    if utc_date is not None:
        ref_utc = int(np.datetime64(utc_date, "ns").astype(np.int64))
        s.reference = f"utc_date {utc_date} from dataset.yaml"
    else:
        ref_utc = path.stat().st_mtime_ns
        s.reference = "the file's modification time"
    ref_gps = int(utc_to_gps_ns(np.array([ref_utc], np.int64))[0])
    if s.gps_first is not None:
        _, s.week_shift = unroll_gps_week(
            np.array([s.gps_first[0]], np.int64), np.array([s.gps_first[1]], np.int64), ref_gps
        )
    for seg in range(len(s.tracker.starts)):
        med = s.pairs.median(seg)
        s.offsets_ns.append(None if med is None else med + s.week_shift * WEEK_NS)
    if s.offsets_ns and all(o is not None for o in s.offsets_ns):
        s.base = TimeBase.GPS
    return s


def _block(s: DfSurvey, rec: Records) -> None:
    s.data_records += int((rec.type != FMT_TYPE).sum())
    for type_, n in enumerate(np.bincount(rec.type, minlength=256).tolist()):
        if n:
            s.per_type[type_] += n
    time_us, has_time = s.clock.times(s.formats, rec)
    s.timed_records += int(has_time.sum())
    s.tracker.push(rec.offset[has_time], time_us[has_time] * 1000)
    for type_ in rec.types():
        idx_all = rec.of_type(type_)
        for fmt, sub in s.formats.split(type_, rec.offset[idx_all]):
            idx = idx_all[sub]
            if fmt is not None:
                _records(s, rec, idx, fmt, time_us[idx])
                continue
            bad = s.formats.unusable.get(type_)
            if bad is None:
                continue
            for spec in s.by_message.get(bad.name, ()):
                key = (spec.name, 0)
                s.counts[key] += len(idx)
                s.first_us.setdefault(key, 0)
                s.last_us[key] = 0
                s.instanced[spec.name] = "I" in bad.columns or "C" in bad.columns
                s.unusable_detail[spec.name] = f"FMT unusable: {bad.reason}"


def _records(
    s: DfSurvey, rec: Records, idx: npt.NDArray[np.intp], fmt: DfFormat, t_us: I64
) -> None:
    name = fmt.name
    for spec in s.by_message.get(name, ()):
        if not spec.present(fmt):
            continue
        inst = instances(spec.instance, fmt, rec, idx)
        s.instanced[spec.name] = fmt.instance_column is not None
        for i in np.flatnonzero(np.bincount(inst)).tolist():
            sel = inst == i
            key = (spec.name, int(i))
            s.counts[key] += int(sel.sum())
            s.first_us.setdefault(key, int(t_us[sel][0]))
            s.last_us[key] = int(t_us[sel][-1])
    _platform_records(s, rec, idx, fmt)
    if name not in ("GPS", "GPS2", "GPA", "GPA2", "ORGN", "EKF1"):
        return
    data = rec.decode(idx, fmt)
    if name == "EKF1":
        cols = [fmt.scaled(data, c) for c in ("PN", "PE", "PD")]
        s.ekf1.append(np.column_stack([t_us.astype(np.float64), *cols]))
        return
    if name == "GPS" and not s.px4:
        ok = fix_status(data) >= FixType.FIX_3D
        if ok.any():
            cols = [fmt.scaled(data, c)[ok] for c in ("Lat", "Lng", "Alt")]
            s.fixes.append(np.column_stack([t_us[ok].astype(np.float64), *cols]))
    if fmt.gps_time is not None:
        _gps(s, rec, idx, data, fmt, t_us)
    elif name in ("GPA", "GPA2") and "Und" in fmt.columns:
        und = fmt.scaled(data, "Und")
        have = und != 0.0
        if have.any():
            mm = np.rint(und[have] * 1e3).astype(np.int64)
            s.undulation_mm.add(np.zeros(len(mm), np.int64), mm)
    elif name == "ORGN":
        for i in np.flatnonzero(np.asarray(data["Type"]) == 0).tolist():
            one = data[i : i + 1]
            lat, lon, alt = (float(fmt.scaled(one, c)[0]) for c in ("Lat", "Lng", "Alt"))
            s.origins.append((int(t_us[i]), lat, lon, alt))


PLATFORM_LINES = 4


def _platform(s: DfSurvey, data: np.ndarray) -> None:
    """The log's first text messages (ArduPilot ``MSG``: firmware, board, frame) or a legacy
    PX4 ``VER`` (``Arch``, ``FwGit``)."""
    names = data.dtype.names or ()
    for row in data:
        parts = [bytes(row[n]).split(b"\0", 1)[0].decode("ascii", "replace").strip() for n in names]
        text = " ".join(p for p in parts if p)
        if text and len(s.platform) < PLATFORM_LINES:
            s.platform.append(text)


def _platform_records(s: DfSurvey, rec: Records, idx: npt.NDArray[np.intp], fmt: DfFormat) -> None:
    """What tells the vehicle kind: the first ``MSG``/``VER`` texts and ArduPlane's
    ``Q_ENABLE`` from ``PARM`` records (the last value logged)."""
    if fmt.name in ("MSG", "VER") and len(s.platform) < PLATFORM_LINES:
        _platform(s, rec.decode(idx[:PLATFORM_LINES], fmt))
    if fmt.name != "PARM" or "Name" not in fmt.columns or "Value" not in fmt.columns:
        return
    data = rec.decode(idx, fmt)
    hit = np.flatnonzero(np.asarray(data["Name"]) == b"Q_ENABLE")
    if len(hit):
        s.q_enable = float(fmt.scaled(data[hit[-1:]], "Value")[0])


def gps_epochs(data: np.ndarray, fmt: DfFormat) -> tuple[I64, npt.NDArray[np.bool_]]:
    """GPS time (ns, before any rollover correction) of GPS records and where it is given:
    week and ms of week, or a legacy PX4 UTC ``GPSTime`` (us)."""
    cols = fmt.gps_time
    n = len(data)
    if cols is None:
        return np.zeros(n, np.int64), np.zeros(n, bool)
    if len(cols) == 2:
        week = np.asarray(data[cols[0]], np.int64)
        tow_ns = np.asarray(data[cols[1]], np.int64) * 1_000_000
        return week * WEEK_NS + tow_ns, week > 0
    utc_us = np.asarray(data[cols[0]], np.int64)
    return utc_to_gps_ns(utc_us * 1000), utc_us > 0


def fix_status(data: np.ndarray) -> npt.NDArray[np.int8]:
    """The fix type of GPS records (``Status``; legacy PX4 ``Fix``)."""
    name = "Status" if "Status" in (data.dtype.names or ()) else "Fix"
    return np.asarray(data[name], np.int8)


def _gps(
    s: DfSurvey,
    rec: Records,
    idx: npt.NDArray[np.intp],
    data: np.ndarray,
    fmt: DfFormat,
    t_us: I64,
) -> None:
    gps_ns, given = gps_epochs(data, fmt)
    ok = given & (fix_status(data) >= 2)
    if len(fmt.gps_time or ()) == 1:
        # Legacy PX4 GPSTime is whole UTC seconds, refreshed once a second while the fixes
        # come at 5 Hz: only the first record of each new second pairs the clocks.
        utc = np.asarray(data["GPSTime"], np.int64)
        prev = np.concatenate([[s.last_gpstime], utc[:-1]])
        ok &= utc != prev
        s.last_gpstime = int(utc[-1]) if len(utc) else s.last_gpstime
    s.gps_rows += int(given.sum())
    if not ok.any():
        return
    if s.gps_first is None:
        first = int(gps_ns[ok][0])
        s.gps_first = (first // WEEK_NS, first % WEEK_NS)
    segs = s.tracker.segment_of(rec.offset[idx][ok])
    s.pairs.add(segs, gps_ns[ok] - t_us[ok] * 1000)
