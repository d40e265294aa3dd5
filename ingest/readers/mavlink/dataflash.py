"""ArduPilot DataFlash logs (``.bin``): self-describing binary records, decoded column-wise.

Each block of the file is framed by a compiled scan (``ingest.readers.mavlink.dfscan``), records are
grouped by type, and each group is decoded with one structured-dtype view built from the
log's own FMT records and pymavlink's format-character table (``ingest.readers.mavlink.dfformat``);
``ingest.readers.mavlink.dfmsgs`` turns IMU, GPS+GPA, XKF1/NKF1, SIM and MAG into canonical
columns.

Streams are keyed ``NAME[i]`` for types with an instance column (``IMU[0]``, ``GPS[1]``,
``XKF1[2]``: the EKF core) and by name otherwise; ``StreamInfo.instance`` is ``i``.

Time (``ingest.readers.mavlink.dfclock``): ``TimeUS`` (us since boot) is paired with GPS time
per boot segment; every stream is then on GPS time, GPS fixes at their own GWk/GMS epoch.

Damage (cases 15-17): garbage between records is skipped, resynchronising on a record whose
successor also frames (DataFlash has no CRC), with runs and bytes counted and their offsets
listed; a trailing partial record is dropped and reported with its offset; FMT records may
appear anywhere (a format applies from its offset on); a type whose FMT uses an unknown
format character is skipped with a note or, when it feeds a selected table, is E-FATAL
naming the type and the offset of its FMT.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence

import numpy as np
import numpy.typing as npt

from navreplay.ingest.arrays import I64
from navreplay.ingest.context import (
    ARDUPILOT_ARMING_EVENTS,
    LogContext,
    ardupilot_error_text,
    ardupilot_event_name,
    ardupilot_mode_name,
    changes,
    decode_text,
)
from navreplay.ingest.detect import DATAFLASH_MAGIC, Detected, Format
from navreplay.ingest.errors import CorruptLogError, UnsupportedFormatError
from navreplay.ingest.platform import from_firmware, with_q_enable
from navreplay.ingest.readers.asof import AsofJoin, Left, through
from navreplay.ingest.readers.base import (
    Batch,
    Inventory,
    LogReader,
    ReadContext,
    Selection,
    StreamInfo,
)
from navreplay.ingest.readers.mavlink.dfclock import DfSurvey, RecordClock, instances, survey
from navreplay.ingest.readers.mavlink.dfformat import DfFormat
from navreplay.ingest.readers.mavlink.dfmsgs import (
    DfExtras,
    DfJoin,
    DfStream,
    finish_gnss,
)
from navreplay.ingest.readers.mavlink.dfscan import Formats, Records, ScanStats, scan_blocks
from navreplay.ingest.readers.mavlink.mavclock import note_week_rollover
from navreplay.ingest.readers.mavlink.mavmsgs import Converted
from navreplay.ingest.schema import EventKind, FixType, TableName

JOIN_TOLERANCE_NS = 50_000_000


class DataFlashReader(LogReader):
    """Reader of one ArduPilot DataFlash ``.bin`` log."""

    format = Format.DATAFLASH

    def __init__(self, detected: Detected, ctx: ReadContext) -> None:
        super().__init__(detected, ctx)
        self._s: DfSurvey | None = None

    def _survey(self) -> DfSurvey:
        if self._s is None:
            cfg = self.ctx.config
            found = survey(self.file, cfg.utc_date if cfg is not None else None)
            if not found.data_records:
                raise CorruptLogError(
                    "no DataFlash data record found (only format definitions, if any): not a "
                    "DataFlash log, or damaged throughout",
                    path=self.file,
                    offset=0,
                )
            if not found.timed_records:
                raise UnsupportedFormatError(
                    f"none of the {found.data_records} DataFlash records carries a time since "
                    "boot (TimeUS, TimeMS, a GPS record's T, a PX4 TIME record): ArduPilot "
                    "logs before Copter 3.1 (2013) time their IMU records only by their order",
                    path=self.file,
                    offset=0,
                    hint="convert the log with a tool that interpolates times from the GPS "
                    "records (pymavlink's DFReader does) to CSV and ingest that",
                )
            self._s = found
        return self._s

    # ----------------------------------------------------------------------------- inventory
    def inventory(self) -> Inventory:
        s = self._survey()
        streams: list[StreamInfo] = []
        for (name, inst), count in sorted(s.counts.items()):
            spec = s.specs[name]
            first, last = s.first_us[(name, inst)], s.last_us[(name, inst)]
            t = s.to_base(np.array([first, last], np.int64), np.array([0, 0], np.int64))
            unusable = s.unusable_detail.get(name)
            streams.append(
                StreamInfo(
                    key=f"{name}[{inst}]" if s.instanced.get(name) else name,
                    msgtype=spec.message,
                    count=count,
                    start_ns=int(t[0]),
                    end_ns=int(t[1]),
                    table=spec.table,
                    time_base=s.base,
                    frame="frd" if spec.table in (TableName.IMU, TableName.MAG) else "ned",
                    instance=inst,
                    detail=unusable or spec.detail,
                )
            )
        joined = {j.message: spec.message for spec in s.specs.values() for j in spec.joins}
        for name, count in s.other_messages().items():
            detail = f"joined into {joined[name]}" if name in joined else "not converted"
            if name in _CONTEXT_MESSAGES:
                detail = "vibration table (context)" if name == "VIBE" else "events table (context)"
            if name == "ORGN":
                detail = "EKF origin of XKF1/NKF1"
            streams.append(StreamInfo(name, name, count, None, None, None, s.base, detail=detail))
        notes = [s.time_note()]
        if s.platform:
            notes.append(f"platform: {'; '.join(s.platform)}")
        notes += [f"FMT of {u.name} at offset {u.offset}: {u.reason}" for u in s.unusable]
        platform = with_q_enable(from_firmware(s.platform), s.q_enable)
        return Inventory(self.path, self.format, tuple(streams), tuple(notes), platform)

    # ---------------------------------------------------------------------------------- read
    def read(self, selections: Sequence[Selection]) -> Iterator[Batch]:
        s = self._survey()
        wanted: dict[str, tuple[DfStream, int]] = {}
        for sel in selections:
            found = _parse_key(sel.key, s.specs)
            if found is not None:
                wanted[sel.key] = found
        self._check_usable(s, wanted)
        extras = s.extras()
        joins = {  # a chain per stream: its rows pass each join in turn
            key: [AsofJoin(j.columns, JOIN_TOLERANCE_NS) for j in spec.joins]
            for key, (spec, _) in wanted.items()
            if spec.joins
        }
        formats = Formats()
        stats = ScanStats()
        clock = RecordClock()
        pending: dict[str, dict[str, int]] = {}  # counters of rows held by a join
        for rec in scan_blocks(self.file, formats, stats):
            t_us, _ = clock.times(formats, rec)
            for key, (spec, inst) in wanted.items():
                batches = self._batches(rec, t_us, formats, spec, inst, key, extras)
                chain = joins.get(key)
                if chain is None:
                    for b in batches:
                        if spec.table != TableName.GNSS:
                            yield b
                            continue
                        cols = dict(b.columns)
                        left = Left(cols.pop("t_ns"), cols, dict(b.nulls), b.offsets)
                        yield _gnss_batch(key, left, extras, "EPH/EPV (PX4)")
                    continue
                for dj, join in zip(spec.joins, chain, strict=True):
                    self._push_right(rec, t_us, formats, dj, spec.instance, inst, join, extras)
                _hold(batches, chain[0], pending.setdefault(key, {}))
                out = through(chain)
                if out is not None:
                    yield _joined_batch(key, spec, out, extras, pending.pop(key, {}))
        for key, chain in joins.items():
            out = through(chain, final=True)
            if out is not None:
                yield _joined_batch(key, wanted[key][0], out, extras, pending.pop(key, {}))
        self._record_damage(stats, formats, s)

    # ------------------------------------------------------------------------------- context
    def context(self) -> LogContext:
        """``MSG`` text, ``MODE`` (named for the firmware of the ``MSG`` banner), ``ARM``,
        ``EV`` and ``ERR`` as events; ``VIBE`` (``VibeX/Y/Z`` m/s^2, clipping counts, per
        ``IMU`` or the ``Clip0..2`` of the three IMUs of logs before 2019) as vibration."""
        s = self._survey()
        out = LogContext(s.base)
        firmware = " ".join(s.platform)
        formats = Formats()
        clock = RecordClock()
        vibe: list[dict[str, np.ndarray]] = []
        for rec in scan_blocks(self.file, formats, ScanStats()):
            t_us, _ = clock.times(formats, rec)
            for name in _CONTEXT_MESSAGES:
                for idx, data, fmt in self._matching(rec, formats, name, 0, 0):
                    t = s.to_base(t_us[idx], rec.offset[idx])
                    if name == "VIBE":
                        vibe.append(_vibe_columns(t, data, fmt))
                    else:
                        _add_events(out, name, t, data, firmware)
        if vibe:
            out.vibration = {k: np.concatenate([v[k] for v in vibe]) for k in vibe[0]}
        if "ARM" in out.events.source:  # ARM states it; EV 10/11 repeat it
            out.events.drop(EventKind.ARMING, "EV")
        return out

    def _check_usable(self, s: DfSurvey, wanted: dict[str, tuple[DfStream, int]]) -> None:
        names = {spec.message for spec, _ in wanted.values()}
        names |= {j.message for spec, _ in wanted.values() for j in spec.joins}
        for u in s.unusable:
            if u.name in names:
                raise CorruptLogError(
                    f"message type {u.name} cannot be decoded: {u.reason}",
                    path=self.file,
                    offset=u.offset,
                    record=f"FMT of {u.name}",
                    hint="the log was written by a logger whose format characters this "
                    "pymavlink version does not know; exclude the stream or update pymavlink",
                )

    def _matching(
        self, rec: Records, formats: Formats, name: str, fixed: int, inst: int
    ) -> Iterator[tuple[npt.NDArray[np.intp], np.ndarray, DfFormat]]:
        """(record indices, decoded records, format) of message ``name``, instance ``inst``
        in a block (``fixed``: the instance of a type without an instance column)."""
        for type_ in formats.types_seen(name):
            idx_all = rec.of_type(type_)
            if not len(idx_all):
                continue
            for fmt, sub in formats.split(type_, rec.offset[idx_all]):
                if fmt is None or fmt.name != name or not len(sub):
                    continue
                idx = idx_all[sub]
                idx = idx[instances(fixed, fmt, rec, idx) == inst]
                if len(idx):
                    yield idx, rec.decode(idx, fmt), fmt

    def _batches(
        self,
        rec: Records,
        t_us: I64,
        formats: Formats,
        spec: DfStream,
        inst: int,
        key: str,
        extras: DfExtras,
    ) -> list[Batch]:
        s = self._survey()
        out: list[Batch] = []
        for idx, data, fmt in self._matching(rec, formats, spec.message, spec.instance, inst):
            conv = spec.convert(data, fmt, extras, t_us[idx])
            t = s.to_base(t_us[idx], rec.offset[idx])
            if spec.table == TableName.GNSS:
                conv.columns["t_fix_ns"] = s.fix_times(data, fmt, t)
            cols = {"t_ns": t, **conv.columns}
            out.append(
                Batch(
                    key,
                    spec.table,
                    cols,
                    rec.offset[idx],
                    conv.nulls,
                    None,
                    conv.counters,
                    conv.info,
                )
            )
        return out

    def _push_right(
        self,
        rec: Records,
        t_us: I64,
        formats: Formats,
        dj: DfJoin,
        fixed: int,
        inst: int,
        join: AsofJoin,
        extras: DfExtras,
    ) -> None:
        """Give ``join`` the records of ``dj``'s message of instance ``inst`` in a block."""
        s = self._survey()
        for idx, data, fmt in self._matching(rec, formats, dj.message, fixed, inst):
            t = s.to_base(t_us[idx], rec.offset[idx])
            join.push_right(t, dj.convert(data, fmt, extras, t_us[idx]).columns)

    # -------------------------------------------------------------------------------- damage
    def _record_damage(self, stats: ScanStats, formats: Formats, s: DfSurvey) -> None:
        dmg = self.damage
        dmg.note(s.time_note())
        dmg.count("records_framed", stats.records)
        s.tracker.note_resets(dmg, reboot="reboot", clock=s.clock_name)
        if s.week_shift:
            how = f", snapped to the epoch nearest {s.reference}"
            note_week_rollover(dmg, s.gps_rows, "GPS records", s.week_shift, how)
        for u in s.unusable:
            dmg.note(f"message type {u.name} skipped: its FMT at offset {u.offset}: {u.reason}")
        for offset, name in formats.redefined:
            dmg.note(f"FMT at offset {offset} redefines {name}: later records use the new layout")
        stats.trailing_header(self.file, DATAFLASH_MAGIC)
        stats.record_garbage(dmg, "DataFlash records")
        stats.record_partial(dmg)


_CONTEXT_MESSAGES = ("MSG", "MODE", "ARM", "EV", "ERR", "VIBE")


def _add_events(out: LogContext, name: str, t: I64, data: np.ndarray, firmware: str) -> None:
    """Events of one message type's records (see ``DataFlashReader.context``)."""
    ev = out.events
    if name == "MSG":
        ev.add(t, EventKind.MESSAGE, decode_text(data["Message"]), name)
    elif name == "MODE":
        modes = data["Mode"].astype(int)
        keep = changes(modes)  # a repeated MODE record (re-entering the mode) is one change
        names = [ardupilot_mode_name(int(m), firmware) for m in modes[keep]]
        ev.add(t[keep], EventKind.MODE, names, name)
    elif name == "ARM":
        armed = data["ArmState"].astype(int)
        ev.add(t, EventKind.ARMING, ["armed" if a else "disarmed" for a in armed], name)
    elif name == "EV":
        ids = data["Id"].astype(int)
        arming = np.isin(ids, list(ARDUPILOT_ARMING_EVENTS))
        names = [ardupilot_event_name(int(i)) for i in ids]
        ev.add(
            t[~arming],
            EventKind.EVENT,
            [n for n, a in zip(names, arming, strict=True) if not a],
            name,
        )
        ev.add(
            t[arming], EventKind.ARMING, [n for n, a in zip(names, arming, strict=True) if a], name
        )
    elif name == "ERR":  # an error, or (code 0) its clearing: an event
        sub, code = data["Subsys"].astype(int), data["ECode"].astype(int)
        texts = [ardupilot_error_text(int(a), int(b)) for a, b in zip(sub, code, strict=True)]
        for kind, pick in ((EventKind.ERROR, code != 0), (EventKind.EVENT, code == 0)):
            ev.add(t[pick], kind, [x for x, p in zip(texts, pick, strict=True) if p], name)


def _vibe_columns(t: I64, data: np.ndarray, fmt: DfFormat) -> dict[str, np.ndarray]:
    """VIBE records as vibration columns: one row per IMU (``IMU`` column, ``Clip``) or, in
    older logs, one row for IMU 0 carrying the levels and the clipping counts of every IMU
    (``Clip0..2``: rows for IMUs 1 and 2 carry their count and NaN levels)."""
    levels = {f"vibe_{a}_mps2": fmt.scaled(data, f"Vibe{a.upper()}") for a in "xyz"}
    if "IMU" in fmt.columns:
        return {
            "t_ns": t,
            "imu": data["IMU"].astype(np.int64),
            **levels,
            "clip_count": fmt.scaled(data, "Clip"),
        }
    clips = [c for c in ("Clip0", "Clip1", "Clip2") if c in fmt.columns]
    n = len(t)
    rows: dict[str, list[np.ndarray]] = {k: [] for k in ("t_ns", "imu", *levels, "clip_count")}
    for i, clip in enumerate(clips or [None]):
        rows["t_ns"].append(t)
        rows["imu"].append(np.full(n, i, np.int64))
        for k, v in levels.items():
            rows[k].append(v if i == 0 else np.full(n, np.nan))
        rows["clip_count"].append(fmt.scaled(data, clip) if clip else np.full(n, np.nan))
    return {k: np.concatenate(v) for k, v in rows.items()}


def _parse_key(key: str, specs: dict[str, DfStream]) -> tuple[DfStream, int] | None:
    name, _, rest = key.partition("[")
    spec = specs.get(name)
    if spec is None:
        return None
    return spec, int(rest.rstrip("]")) if rest else spec.instance


def _hold(batches: list[Batch], join: AsofJoin, counters: dict[str, int]) -> None:
    """Give a join the rows of ``batches``, adding their counters to ``counters``."""
    for b in batches:
        cols = dict(b.columns)
        join.push_left(Left(cols.pop("t_ns"), cols, dict(b.nulls), b.offsets))
        for name, n in b.counters.items():
            counters[name] = counters.get(name, 0) + n


def _joined_batch(
    key: str, spec: DfStream, out: Left, extras: DfExtras, counters: dict[str, int]
) -> Batch:
    """A stream's rows after their join, with the counters of the conversions they came from:
    a GPS batch finished (its counters its own), any other as it is."""
    if spec.table == TableName.GNSS:
        return _gnss_batch(key, out, extras)
    cols = {"t_ns": out.t, **out.columns}
    return Batch(key, spec.table, cols, out.offsets, out.nulls, None, counters)


def _gnss_batch(
    key: str, out: Left, extras: DfExtras, accuracy: str = "from GPA (same instance)"
) -> Batch:
    """A GPS batch after its GPA join: fix epochs as t_ns, heights and accuracies finished."""
    cols = out.columns
    t = cols.pop("t_fix_ns")
    conv = Converted(cols, out.nulls)
    finish_gnss(conv, extras)
    conv.counters["no_fix"] = int((cols["fix_type"] < FixType.FIX_2D).sum())
    info = {"time": "the GPS time of each fix (week and ms of week, or UTC)"}
    if accuracy:
        info["accuracy"] = accuracy
    return Batch(
        key,
        TableName.GNSS,
        {"t_ns": t, **conv.columns},
        out.offsets,
        conv.nulls,
        None,
        conv.counters,
        info,
    )
