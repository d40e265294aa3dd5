"""NMEA 0183 receiver logs: one ``gnss`` row per GGA epoch (or ``truth`` for a reference
receiver), decoded by ``ingest.readers.gnss._nmea``.

Per epoch (one output cycle of the receiver):

- position from GGA; ``alt_m`` = altitude above mean sea level + geoid separation (the
  ellipsoidal height), NaN when the separation is missing (counted);
- ``fix_type`` from the GGA quality: 0 no fix, 1 GPS fix (2-D when GSA says so, else 3-D),
  2 DGPS, 3 PPS (3-D), 4 RTK fixed, 5 RTK float, 6 dead reckoning and 7/8 manual/simulated
  as no fix (the position is kept, but it is not a GNSS measurement; counted);
- velocity from RMC speed/course (VTG when the epoch has no valid RMC): ``vel_n``/``vel_e``;
  ``vel_d`` is never reported (null);
- ``num_sats``: satellites used, counted from the GSA sentences (GGA caps its count at 12 on
  many receivers), GGA's count when the epoch has no GSA; extra columns ``pdop``, ``hdop``,
  ``vdop`` and ``sats_in_view`` (GSV);
- ``h_acc_m`` = sqrt((sigma_lat^2 + sigma_lon^2) / 2) and ``v_acc_m`` = sigma_alt from GST,
  null without GST.

GSV carries elevation, azimuth and C/N0 per satellite but no pseudoranges, so nothing here can
fill ``gnss_obs``; ``--list`` says so.

Time: GGA times are UTC times of day; the date comes from RMC (or ZDA) of the file, from the
previous epoch (a time of day that goes backwards is the next day), or from ``utc_date`` in the
dataset descriptor. UTC is converted to GPS time with the leap-second table, and the stream is
declared GPS. A file without any date stays on the ``recorder`` base counting seconds from
midnight UTC of its first day.

Which GGA feeds which table: each talker's GGA (``GNGGA``, ``GPGGA`` ...) is one stream for the
``gnss`` table; when ``truth.topic`` in the descriptor names it, it fills ``truth`` instead (a
reference receiver such as a NovAtel SPAN logging GGA).

Bad input: sentences with a wrong or missing checksum and lines that are not sentences are
skipped and counted with their line numbers (E-RECOVER; ``--strict`` makes them errors); a last
line without a newline is a truncated write and dropped. Row offsets are GGA line numbers.
"""

from __future__ import annotations

import math
from collections.abc import Iterator, Sequence
from dataclasses import dataclass, field

import numpy as np

from navreplay.ingest.arrays import Bools
from navreplay.ingest.damage import Completeness, Defect
from navreplay.ingest.detect import Detected, Format
from navreplay.ingest.readers._lines import listed, partial_line_defect
from navreplay.ingest.readers.base import (
    Batch,
    Inventory,
    LogReader,
    ReadContext,
    Selection,
    StreamInfo,
)
from navreplay.ingest.readers.gnss._nmea import (
    Epoch,
    EpochBuilder,
    Gga,
    checksum_ok,
    date_ymd,
    time_of_day_s,
)
from navreplay.ingest.schema import FixType, TableName
from navreplay.ingest.timebase import NS_PER_S, TimeBase, utc_to_gps_ns

_DAY_NS = 86_400 * NS_PER_S
_HALF_DAY_S = 43_200.0
_QUALITY = {
    0: FixType.NO_FIX,
    1: FixType.FIX_3D,
    2: FixType.DGPS,
    3: FixType.FIX_3D,
    4: FixType.RTK_FIXED,
    5: FixType.RTK_FLOAT,
}
_OTHER = {
    "RMC": "date, speed and course: joined to the GGA of its epoch",
    "VTG": "speed and course: joined when the epoch has no valid RMC",
    "GSA": "satellites used and DOP: num_sats, pdop, hdop, vdop",
    "GSV": "satellites in view (elevation, azimuth, C/N0): sats_in_view; no pseudoranges, so "
    "not convertible to gnss_obs",
    "GST": "position error sigmas: h_acc_m, v_acc_m",
    "GLL": "position (duplicates GGA): not used",
    "ZDA": "date: used for the time base",
}


@dataclass
class _Rejects:
    checksum: list[int] = field(default_factory=list)
    garbage: list[int] = field(default_factory=list)
    partial: int | None = None


class NmeaReader(LogReader):
    """Reader of one NMEA 0183 text log (see the module docstring)."""

    format = Format.NMEA
    offsets_are_lines = True

    def __init__(self, detected: Detected, ctx: ReadContext) -> None:
        super().__init__(detected, ctx)
        cfg = ctx.config
        self.truth_key = cfg.truth.topic if cfg is not None else None
        self.config_date = _config_date(cfg.utc_date if cfg is not None else None)

    # ------------------------------------------------------------------------------ inventory
    def inventory(self) -> Inventory:
        counts: dict[str, int] = {}
        first_tod: dict[str, float] = {}
        last_tod: dict[str, float] = {}
        date: tuple[int, int, int] | None = None
        rejected = 0
        with self.file.open("rb") as fh:
            for raw in fh:
                line = raw.rstrip(b"\r\n")
                if not checksum_ok(line):
                    rejected += bool(line)
                    continue
                address = line[1:].split(b",", 1)[0].decode("ascii", "replace")
                counts[address] = counts.get(address, 0) + 1
                if address.endswith("GGA"):
                    tod = time_of_day_s(line.split(b",", 2)[1].decode("ascii", "replace"))
                    first_tod.setdefault(address, tod)
                    last_tod[address] = tod
                elif date is None and address[2:] in ("RMC", "ZDA"):
                    date = _sentence_date(line)
        date = date or self.config_date
        base = TimeBase.GPS if date is not None else TimeBase.RECORDER
        streams = [
            self._gga_info(a, n, first_tod, last_tod, date, base)
            for a, n in counts.items()
            if a.endswith("GGA")
        ]
        by_kind: dict[str, list[str]] = {}
        for a in counts:
            if not a.endswith("GGA") and len(a) == 5:
                by_kind.setdefault(a[2:], []).append(a)
        for kind, addresses in sorted(by_kind.items()):
            streams.append(
                StreamInfo(
                    key=kind,
                    msgtype=",".join(sorted(addresses)),
                    count=sum(counts[a] for a in addresses),
                    start_ns=None,
                    end_ns=None,
                    table=None,
                    time_base=base,
                    detail=_OTHER.get(kind, "not used"),
                )
            )
        notes = [
            "UTC -> GPS time with the leap-second table"
            if date
            else "no date in the file (RMC/ZDA) nor utc_date in dataset.yaml: times count "
            "seconds from midnight UTC (time base recorder)"
        ]
        if rejected:
            notes.append(
                f"{rejected} lines are not sentences with a valid checksum (skipped; their line "
                "numbers are in the ingest report)"
            )
        return Inventory(self.path, self.format, tuple(streams), tuple(notes))

    def _gga_info(
        self,
        address: str,
        count: int,
        first: dict[str, float],
        last: dict[str, float],
        date: tuple[int, int, int] | None,
        base: TimeBase,
    ) -> StreamInfo:
        table = TableName.TRUTH if address == self.truth_key else TableName.GNSS
        start = _stamp(date, first[address]) if not math.isnan(first[address]) else None
        end = None
        if start is not None and not math.isnan(last[address]):
            end = start + round((last[address] - first[address]) % 86_400 * NS_PER_S)
        role = "reference receiver (dataset.yaml truth.topic)" if table == TableName.TRUTH else ""
        return StreamInfo(
            key=address,
            msgtype=address,
            count=count,
            start_ns=start,
            end_ns=end,
            table=table,
            time_base=base,
            frame="ned",
            detail=role or "fixes: position, quality, satellites",
        )

    # ----------------------------------------------------------------------------------- read
    def read(self, selections: Sequence[Selection]) -> Iterator[Batch]:
        keys = {s.key: s.table for s in selections if s.key.endswith("GGA")}
        if not keys:
            return
        rows: dict[str, list[_Row]] = {k: [] for k in keys}
        rejects = _Rejects()
        builder = EpochBuilder()
        dates = _Dates(self.config_date)
        for epoch in self._epochs(builder, rejects):
            row = _Row(epoch, dates.assign(epoch))
            for key in keys:
                if key[:2] in epoch.gga:
                    rows[key].append(row)
            if not dates.known:
                continue  # rows wait for the first date (a file without one is held whole)
            for key, table in keys.items():
                if len(rows[key]) >= self.ctx.batch_rows:
                    dates.resolve(rows[key])
                    yield self._batch(key, table, rows[key], dates)
                    rows[key] = []
        for key, table in keys.items():
            if rows[key]:
                dates.resolve(rows[key])
                yield self._batch(key, table, rows[key], dates)
        self._report(rejects, builder)

    def _epochs(self, builder: EpochBuilder, rejects: _Rejects) -> Iterator[Epoch]:
        with self.file.open("rb") as fh:
            for number, raw in enumerate(fh, start=1):
                if not raw.endswith(b"\n"):
                    rejects.partial = number
                    break
                line = raw.rstrip(b"\r\n")
                if not line:
                    continue
                ok = checksum_ok(line)
                if ok is None:
                    rejects.garbage.append(number)
                    continue
                if not ok:
                    rejects.checksum.append(number)
                    continue
                fields = line[1:].rpartition(b"*")[0].decode("ascii", "replace").split(",")
                done = builder.add(fields, number)
                if done is not None:
                    yield done
        done = builder.finish()
        if done is not None:
            yield done

    def _batch(self, key: str, table: TableName, rows: list[_Row], dates: _Dates) -> Batch:
        talker = key[:2]
        ggas = [r.epoch.gga[talker] for r in rows]
        tod_ns = np.array([round(r.epoch.tod_s * NS_PER_S) for r in rows], np.int64)
        t_ns = np.array([r.day or 0 for r in rows], np.int64) * _DAY_NS + tod_ns
        if dates.known:
            t_ns = utc_to_gps_ns(t_ns)
        lat = np.array([g.lat_deg for g in ggas])
        lon = np.array([g.lon_deg for g in ggas])
        sep = np.array([g.geoid_sep_m for g in ggas])
        alt = np.array([g.alt_msl_m for g in ggas]) + sep
        alt[np.isnan(lat) | np.isnan(lon)] = np.nan  # no position: no height either
        speed = np.array([r.epoch.speed_mps for r in rows])
        course = np.array([r.epoch.course_deg for r in rows])
        course = np.where(np.isnan(course) & (speed == 0.0), 0.0, course)
        rad = np.radians(course)
        cols: dict[str, np.ndarray] = {
            "t_ns": t_ns,
            "lat_deg": lat,
            "lon_deg": lon,
            "alt_m": alt,
            "vel_n_mps": speed * np.cos(rad),
            "vel_e_mps": speed * np.sin(rad),
        }
        no_vel = np.isnan(speed) | np.isnan(course)
        nulls = {"vel_n_mps": no_vel, "vel_e_mps": no_vel}
        counters = {"geoid_separation_missing": int(np.isnan(sep).sum())}
        if table == TableName.GNSS:
            self._gnss_columns(cols, nulls, counters, rows, ggas)
        offsets = np.array([g.line for g in ggas], np.int64)
        info = {
            "time": "UTC date + time of day -> GPS"
            if dates.known
            else "seconds from midnight UTC (no date)",
            "altitude": "GGA altitude (MSL) + geoid separation = ellipsoidal height",
            "velocity": "RMC (or VTG) speed and course -> north/east; vel_d not provided",
        }
        return Batch(
            key,
            table,
            cols,
            offsets,
            nulls=nulls,
            counters={k: v for k, v in counters.items() if v},
            info=info,
        )

    @staticmethod
    def _gnss_columns(
        cols: dict[str, np.ndarray],
        nulls: dict[str, Bools],
        counters: dict[str, int],
        rows: list[_Row],
        ggas: list[Gga],
    ) -> None:
        eps = [r.epoch for r in rows]
        quality = np.array([g.quality for g in ggas])
        mode = np.array([ep.nav_mode for ep in eps])
        fix = np.array([_QUALITY.get(q, FixType.NO_FIX) for q in quality.tolist()], np.int8)
        fix[(quality == 1) & (mode == 2)] = FixType.FIX_2D
        no_pos = np.isnan(cols["lat_deg"]) | np.isnan(cols["lon_deg"])
        fix[no_pos] = FixType.NO_FIX
        cols["fix_type"] = fix
        for q in sorted(set(quality.tolist()) - set(_QUALITY)):
            counters[f"quality_{q}_not_a_gnss_fix"] = int((quality == q).sum())
        used = np.array(
            [
                float(len(ep.used)) if ep.used else g.num_sats
                for ep, g in zip(eps, ggas, strict=True)
            ]
        )
        cols["num_sats"] = np.nan_to_num(used, nan=0.0).astype(np.int16)
        nulls["num_sats"] = np.isnan(used)
        for name in ("pdop", "hdop", "vdop"):
            values = np.array([getattr(ep, name) for ep in eps])
            if name == "hdop":
                gga_hdop = np.array([g.hdop for g in ggas])
                values = np.where(np.isnan(values), gga_hdop, values)
            cols[name] = values
            nulls[name] = np.isnan(values)
        view = np.array([float(len(ep.in_view)) for ep in eps])
        cols["sats_in_view"] = view
        nulls["sats_in_view"] = view == 0
        sig = np.array([ep.sigma_m or (math.nan,) * 3 for ep in eps])
        cols["h_acc_m"] = np.sqrt(0.5 * (sig[:, 0] ** 2 + sig[:, 1] ** 2))
        cols["v_acc_m"] = sig[:, 2]
        nulls["h_acc_m"] = nulls["v_acc_m"] = np.isnan(sig[:, 0])

    def _report(self, rejects: _Rejects, builder: EpochBuilder) -> None:
        d = self.damage
        for name, n in sorted(builder.sentences.items()):
            d.count(f"sentences_{name}", n)
        if builder.orphans:
            d.count("sentences_before_first_epoch", builder.orphans)
        if builder.repeated:
            d.count("gga_repeated_within_an_epoch", builder.repeated)
        if rejects.checksum:
            d.record(
                Defect(
                    Completeness.CHECKSUM_MISMATCH,
                    f"{len(rejects.checksum)} sentences with a wrong checksum skipped "
                    f"(lines {listed(rejects.checksum)})",
                    offset=rejects.checksum[0],
                )
            )
        if rejects.garbage:
            d.record(
                Defect(
                    Completeness.BAD_DATA_SKIPPED,
                    f"{len(rejects.garbage)} lines that are not NMEA sentences (no '$' "
                    f"or no checksum) skipped (lines {listed(rejects.garbage)})",
                    offset=rejects.garbage[0],
                )
            )
        if rejects.partial is not None:
            d.record(partial_line_defect(rejects.partial))


@dataclass
class _Row:
    """An epoch with a GGA for the stream, and its day (days since 1970) once known."""

    epoch: Epoch
    day: int | None


class _Dates:
    """UTC dates of epochs: from RMC/ZDA, carried forward, advanced when the time of day goes
    back by more than half a day (midnight; smaller steps are late epochs for the stream
    hygiene); epochs before the first date get it (or the day before, when their
    time of day is later). Without any date, days count from 0 (time base recorder)."""

    def __init__(self, configured: tuple[int, int, int] | None) -> None:
        self.day: int | None = None if configured is None else _days(configured)
        self.known = self.day is not None
        self.first: tuple[int, float] | None = None
        self.last_tod = math.nan
        self.wraps = 0

    def assign(self, epoch: Epoch) -> int | None:
        """The day of ``epoch`` (None while no date is known yet)."""
        backwards = epoch.tod_s < self.last_tod - _HALF_DAY_S  # midnight, not a late epoch
        if not math.isnan(epoch.tod_s):
            self.last_tod = epoch.tod_s
        self.wraps += int(backwards)
        if epoch.date is not None:
            self.day, self.known = _days(epoch.date), True
        elif self.day is not None and backwards:
            self.day += 1
        if self.day is not None and self.first is None:
            self.first = (self.day, epoch.tod_s)
        return self.day

    def resolve(self, rows: list[_Row]) -> None:
        """Give rows that predate the first date their day (or a day count, with no date)."""
        wraps, last = 0, math.nan
        for r in rows:
            if r.day is not None:
                continue
            if self.first is not None:
                day0, tod0 = self.first
                r.day = day0 - 1 if r.epoch.tod_s > tod0 else day0
            else:
                wraps += int(r.epoch.tod_s < last - _HALF_DAY_S)
                last = r.epoch.tod_s if not math.isnan(r.epoch.tod_s) else last
                r.day = wraps


def _days(ymd: tuple[int, int, int]) -> int:
    y, m, d = ymd
    return int(np.datetime64(f"{y:04d}-{m:02d}-{d:02d}", "D").astype(np.int64))


def _stamp(date: tuple[int, int, int] | None, tod_s: float) -> int:
    t = round(tod_s * NS_PER_S)
    if date is None:
        return t
    return int(utc_to_gps_ns(np.array([_days(date) * _DAY_NS + t], np.int64))[0])


def _sentence_date(line: bytes) -> tuple[int, int, int] | None:
    f = line[1:].rpartition(b"*")[0].decode("ascii", "replace").split(",")
    if f[0].endswith("RMC"):
        return date_ymd(f[9]) if len(f) > 9 else None
    if len(f) > 4 and all(x.isdigit() for x in f[2:5]):
        return (int(f[4]), int(f[3]), int(f[2]))
    return None


def _config_date(text: str | None) -> tuple[int, int, int] | None:
    if text is None:
        return None
    y, m, d = (int(p) for p in text.split("-"))
    return (y, m, d)
