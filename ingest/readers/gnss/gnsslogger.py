"""Android GnssLogger text logs (v1.4 to v3): ``Raw`` -> ``gnss_obs``, ``Fix`` -> ``gnss``,
``Accel`` + ``Gyro`` -> ``imu``.

The log defines each record type's columns in its ``#`` header (``# Raw,utcTimeMillis,
TimeNanos,...``); fields are looked up by those names, so the versions' different column sets
(v1.4 ``Latitude``/``(UTC)TimeInMs``, v2 ``LatitudeDegrees``/``UnixTimeMillis`` ...) read alike.

``Raw`` (with a RINEX navigation file given in the same ingest, as for RINEX observations):
GPS L1 pseudoranges by Google's raw convention (``ingest.gnss.android``), satellite states from the
broadcast ephemeris (``ingest.gnss.obsgeometry``), ``pseudorange_rate_mps`` from
``PseudorangeRateMetersPerSecond``, ``cn0_dbhz`` from ``Cn0DbHz``, sigmas from the reported
uncertainties. Rows of other constellations and rows failing the validity checks are
excluded and counted per reason (table counters ``excluded_<reason>``).

``Fix`` of the ``gps`` provider -> ``gnss`` on UTC (``UnixTimeMillis``), with ``vel_n/e`` from
``SpeedMps`` and ``BearingDegrees`` when the log has a bearing (else null), ``h_acc_m`` =
``AccuracyMeters / 1.5096`` (Android reports the radius of 68 % horizontal confidence, 1.5096
per-axis sigmas for a circular normal), ``v_acc_m`` from ``VerticalAccuracyMeters`` when
present. Other providers (fused, network) are listed, not used.

``Accel`` + ``Gyro`` (calibrated; the ``Uncal`` pair when only those were logged) -> ``imu``:
the phone's sensor frame is x to the right edge, y to the top edge, z out of the screen; body
FRD is taken as forward = top edge, right = right edge, down = into the screen:
``(x, y, z)_FRD = (y, x, -z)_phone`` for both specific force and rate (a phone lying screen
up, top edge forward, is a level body; at rest ``acc_z`` is about -9.8). Gyro samples are
interpolated linearly to the accelerometer's times (rows outside the gyro's span dropped).
Sensor times are ``elapsedRealtimeNanos``; they are put on UTC with the median of
``utcTimeMillis - elapsedRealtimeNanos`` over the sensor rows (the wall clock at the sensor
callback: a few milliseconds). v1.4 logs have no sensor records.

Damage: a line whose field count differs from its header is skipped (``bad_data_skipped``,
its line number); a last line without its newline is dropped (``truncated``); an unreadable
number leaves NaN in that field and is counted per record type. Blank lines and lines of
record types not used (``Mag``, ``Status``, ``Nav`` ...) are counted in ``counters``.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
import pymap3d

from navreplay.ingest.arrays import F64, I64
from navreplay.ingest.damage import Completeness, Defect
from navreplay.ingest.detect import Detected, Format
from navreplay.ingest.errors import IngestError
from navreplay.ingest.gnss.android import CONSTELLATIONS, RawColumns, pseudoranges
from navreplay.ingest.gnss.obsgeometry import observation_geometry
from navreplay.ingest.gnss.rinexnav import NavData, Unreported, merge, read_nav
from navreplay.ingest.readers.base import (
    Batch,
    Inventory,
    LogReader,
    ReadContext,
    Selection,
    StreamInfo,
    selected_tables,
)
from navreplay.ingest.schema import FixType, TableName
from navreplay.ingest.timebase import TimeBase

RAW_KEY = "Raw:GPS"
IMU_KEYS = {
    "imu:Accel+Gyro": ("Accel", "Gyro"),
    "imu:UncalAccel+UncalGyro": ("UncalAccel", "UncalGyro"),
}
SIGMA_PER_R68 = 1.5096
_ALIASES = {
    "lat": ("LatitudeDegrees", "Latitude"),
    "lon": ("LongitudeDegrees", "Longitude"),
    "alt": ("AltitudeMeters", "Altitude"),
    "speed": ("SpeedMps", "Speed"),
    "acc": ("AccuracyMeters", "Accuracy"),
    "bearing": ("BearingDegrees", "Bearing"),
    "time": ("UnixTimeMillis", "(UTC)TimeInMs", "utcTimeMillis"),
    "vacc": ("VerticalAccuracyMeters",),
    "sacc": ("SpeedAccuracyMps",),
}


@dataclass
class _Records:
    """One record type: its header columns, its rows' fields and line numbers."""

    columns: list[str]
    rows: list[list[str]] = field(default_factory=list)
    lines: list[int] = field(default_factory=list)
    unreadable: set[tuple[int, int]] = field(default_factory=set)  # (row, column)

    def index(self, *names: str) -> int | None:
        for name in names:
            if name in self.columns:
                return self.columns.index(name)
        return None

    def floats(self, *names: str) -> F64:
        """The column as float64: blank -> NaN, unreadable -> NaN (counted)."""
        k = self.index(*names)
        if k is None:
            return np.full(len(self.rows), np.nan)
        text = self._text(k)
        text[text == ""] = "nan"
        out, _ = self._parse(text, k, np.float64, np.nan, float)
        return out

    def ints(self, *names: str) -> tuple[I64, npt.NDArray[np.bool_]]:
        """Exact int64 values (``FullBiasNanos`` needs all 19 digits) and where present."""
        k = self.index(*names)
        if k is None:
            return np.zeros(len(self.rows), np.int64), np.zeros(len(self.rows), bool)
        text = self._text(k)
        present = text != ""
        text[~present] = "0"
        out, unreadable = self._parse(text, k, np.int64, 0, _int)
        present[unreadable] = False
        return out, present

    def _text(self, k: int) -> npt.NDArray[np.str_]:
        return np.char.strip(np.array([r[k] for r in self.rows], dtype=str))

    def _parse(
        self,
        text: npt.NDArray[np.str_],
        k: int,
        dtype: type[np.float64] | type[np.int64],
        fill: float,
        parse: Callable[[str], float],
    ) -> tuple[npt.NDArray[Any], list[int]]:
        """Column ``k``'s ``text`` as ``dtype``, and which rows are unreadable (``fill``,
        counted). numpy parses the whole column at once; only if that fails is each value
        parsed on its own with ``parse``."""
        try:
            return np.asarray(text.astype(dtype), dtype=dtype), []
        except ValueError:
            out = np.full(text.size, fill, dtype)
            unreadable: list[int] = []
            for i, v in enumerate(text.tolist()):
                try:
                    out[i] = parse(v)
                except ValueError:
                    self.unreadable.add((i, k))
                    unreadable.append(i)
            return out, unreadable


def _int(v: str) -> int:
    """An integer field, also when written as a float (``"12.0"``)."""
    try:
        return int(v)
    except ValueError:
        return int(float(v))


class GnssLoggerReader(LogReader):
    """An Android GnssLogger text log (see the module docstring)."""

    format = Format.GNSSLOGGER
    offsets_are_lines = True

    def __init__(self, detected: Detected, ctx: ReadContext) -> None:
        super().__init__(detected, ctx)
        self._records: dict[str, _Records] | None = None
        self._nav_files = [
            d for d in ctx.siblings if d.format == Format.RINEX and d.variant.startswith("nav")
        ]
        self.version = ""

    # ------------------------------------------------------------------------------ parsing
    def _parse(self) -> dict[str, _Records]:
        if self._records is not None:
            return self._records
        records: dict[str, _Records] = {}
        other = 0
        with self.path.open("r", encoding="utf-8", errors="replace", newline="") as fh:
            for number, raw in enumerate(fh, start=1):
                if not raw.endswith("\n"):
                    self.damage.record(
                        Defect(
                            Completeness.TRUNCATED,
                            f"the last line ({number}) is cut short: dropped",
                            offset=number,
                        )
                    )
                    break
                line = raw.strip()
                if line.startswith("#"):
                    self._header_line(line[1:].strip(), records)
                    continue
                kind, _, rest = line.partition(",")
                rec = records.get(kind)
                if rec is None:
                    other += 1
                    continue
                fields = [kind, *rest.split(",")]
                if len(fields) != len(rec.columns):
                    self.damage.record(
                        Defect(
                            Completeness.BAD_DATA_SKIPPED,
                            f"{kind} record at line {number} has {len(fields)} fields, its "
                            f"header {len(rec.columns)}: skipped",
                            offset=number,
                        )
                    )
                    continue
                rec.rows.append(fields)
                rec.lines.append(number)
        unused = sum(len(r.rows) for k, r in records.items() if k not in _USED)
        self.damage.count("lines_not_used", other + unused)
        self._records = records
        return records

    def _header_line(self, text: str, records: dict[str, _Records]) -> None:
        if text.startswith("Version:"):
            self.version = text.split(":", 1)[1].split(maxsplit=1)[0].rstrip(",")
            return
        kind, _, rest = text.partition(",")
        if kind and rest and kind.isalpha():
            records[kind] = _Records([c.strip() for c in text.split(",")])

    # ---------------------------------------------------------------------------- inventory
    def inventory(self) -> Inventory:
        recs = self._parse()
        streams: list[StreamInfo] = []
        raw = recs.get("Raw")
        if raw is not None and raw.rows:
            streams.append(self._raw_info(raw))
        fix = recs.get("Fix")
        if fix is not None and fix.rows:
            streams.extend(self._fix_infos(fix))
        for key, (a, g) in IMU_KEYS.items():
            ra, rg = recs.get(a), recs.get(g)
            if ra is not None and rg is not None and ra.rows and rg.rows:
                calibrated = key == "imu:Accel+Gyro"
                usable = calibrated or not recs.get("Accel") or not recs["Accel"].rows
                t = ra.floats("elapsedRealtimeNanos")
                streams.append(
                    StreamInfo(
                        key=key,
                        msgtype=f"{a} + {g}",
                        count=len(ra.rows),
                        start_ns=None,
                        end_ns=None,
                        table=TableName.IMU if usable else None,
                        time_base=TimeBase.UTC,
                        frame="frd",
                        detail=f"{len(ra.rows)} {a}, {len(rg.rows)} {g}; phone axes -> FRD "
                        f"(y, x, -z); span {np.ptp(t) * 1e-9 if t.size else 0:.2f} s"
                        + ("" if usable else "; the calibrated pair is used"),
                    )
                )
        notes = (
            f"GnssLogger {self.version or 'version unknown'}",
            *tuple(f"{k}: {len(r.rows)} records" for k, r in sorted(recs.items())),
        )
        return Inventory(self.path, self.format, tuple(streams), notes)

    def _raw_info(self, raw: _Records) -> StreamInfo:
        cols = _raw_columns(raw)
        gps = cols.constellation == 1
        t = cols.time_nanos - cols.full_bias_nanos
        t = t[gps & cols.full_bias_present]
        others = {
            CONSTELLATIONS.get(int(c), str(c)): int(n)
            for c, n in zip(*np.unique(cols.constellation[~gps], return_counts=True), strict=True)
        }
        detail = f"{len(raw.rows)} Raw rows, {int(gps.sum())} GPS"
        if others:
            detail += "; not placed (no orbit model): " + ", ".join(
                f"{k} {v}" for k, v in others.items()
            )
        if not self._nav_files:
            detail += "; needs the RINEX navigation file: pass it with the log"
        return StreamInfo(
            key=RAW_KEY,
            msgtype="GnssMeasurement (Raw)",
            count=int(gps.sum()),
            start_ns=int(t.min()) if t.size else None,
            end_ns=int(t.max()) if t.size else None,
            table=TableName.GNSS_OBS if self._nav_files else None,
            time_base=TimeBase.GPS,
            detail=detail,
        )

    def _fix_infos(self, fix: _Records) -> list[StreamInfo]:
        k = fix.index("Provider")
        providers = [r[k].strip() for r in fix.rows] if k is not None else ["gps"] * len(fix.rows)
        t = fix.floats(*_ALIASES["time"]) * 1e6
        out = []
        for name in sorted(set(providers)):
            mask = np.array([p == name for p in providers])
            tm = t[mask & np.isfinite(t)]
            gnss = name.lower() == "gps"
            out.append(
                StreamInfo(
                    key=f"Fix:{name}",
                    msgtype="Location (Fix)",
                    count=int(mask.sum()),
                    start_ns=int(tm.min()) if tm.size else None,
                    end_ns=int(tm.max()) if tm.size else None,
                    table=TableName.GNSS if gnss else None,
                    time_base=TimeBase.UTC,
                    detail="" if gnss else f"provider {name}: not a GNSS receiver fix",
                )
            )
        return out

    # --------------------------------------------------------------------------------- read
    def read(self, selections: Sequence[Selection]) -> Iterator[Batch]:
        wanted = selected_tables(selections)
        recs = self._parse()
        for key in wanted:
            if key == RAW_KEY:
                yield self._raw_batch(recs["Raw"])
            elif key.startswith("Fix:"):
                yield self._fix_batch(recs["Fix"], key.split(":", 1)[1])
            elif key in IMU_KEYS:
                a, g = IMU_KEYS[key]
                yield self._imu_batch(recs[a], recs[g], key)
        for kind, rec in recs.items():
            if rec.unreadable:
                self.damage.count(f"unreadable_numbers_{kind}", len(rec.unreadable))

    def _nav(self) -> NavData:
        if not self._nav_files:
            raise IngestError(
                "Android raw measurements without a navigation file",
                path=self.path,
                hint="pass the RINEX navigation file of the same day in the same ingest",
            )
        return merge([read_nav(d.path, d.variant, Unreported(d.path)) for d in self._nav_files])

    def _raw_batch(self, raw: _Records) -> Batch:
        cols = _raw_columns(raw)
        pr = pseudoranges(cols)
        order = np.argsort(pr.t_ns, kind="stable")
        rows = pr.rows[order]
        t, prn, rng = pr.t_ns[order], pr.prn[order], pr.pseudorange_m[order]
        nav = self._nav()
        geo = observation_geometry(
            nav.ephemeris, t, prn, rng, approx_ecef_m=self._approx(), klobuchar=nav.klobuchar
        )
        keep = geo.keep
        sel = rows[keep]
        counters = {f"excluded_{k}": v for k, v in pr.excluded.items()}
        counters.update(geo.counters)
        jumps = np.count_nonzero(np.diff(cols.full_bias_nanos[cols.full_bias_present]) != 0)
        counters["full_bias_changes"] = int(jumps)
        columns: dict[str, np.ndarray] = {
            "t_ns": t[keep],
            "sv": np.array([f"G{p:02d}" for p in prn[keep]]),
            "pseudorange_m": rng[keep],
            "pseudorange_rate_mps": cols.prr_mps[sel],
            "cn0_dbhz": cols.cn0_dbhz[sel],
            "pseudorange_std_m": pr.pseudorange_std_m[order][keep],
            "pseudorange_rate_std_mps": cols.prr_unc_mps[sel],
            **geo.columns,
        }
        info = {
            "convention": "Google raw: t_rx = TimeNanos + TimeOffsetNanos - FullBiasNanos - "
            "BiasNanos; GPS L1 only",
        }
        lines = np.asarray(raw.lines, dtype=np.int64)[sel]
        return Batch(RAW_KEY, TableName.GNSS_OBS, columns, lines, counters=counters, info=info)

    def _approx(self) -> F64 | None:
        fix = (self._records or {}).get("Fix")
        if fix is None or not fix.rows:
            return None
        lat, lon, alt = (fix.floats(*_ALIASES[k]) for k in ("lat", "lon", "alt"))
        ok = np.flatnonzero(np.isfinite(lat) & np.isfinite(lon) & np.isfinite(alt))
        if not ok.size:
            return None
        i = int(ok[0])
        return np.array(pymap3d.geodetic2ecef(lat[i], lon[i], alt[i]), dtype=np.float64)

    def _fix_batch(self, fix: _Records, provider: str) -> Batch:
        k = fix.index("Provider")
        mask = np.array([k is None or r[k].strip() == provider for r in fix.rows])
        get = {name: fix.floats(*names)[mask] for name, names in _ALIASES.items()}
        t = get["time"]
        ok = np.isfinite(t)
        n = int(ok.sum())
        speed, bearing = get["speed"][ok], np.radians(get["bearing"][ok])
        columns: dict[str, np.ndarray] = {
            "t_ns": np.round(t[ok] * 1e6).astype(np.int64),
            "lat_deg": get["lat"][ok],
            "lon_deg": get["lon"][ok],
            "alt_m": get["alt"][ok],
            "vel_n_mps": speed * np.cos(bearing),
            "vel_e_mps": speed * np.sin(bearing),
            "vel_d_mps": np.full(n, np.nan),
            "h_acc_m": get["acc"][ok] / SIGMA_PER_R68,
            "v_acc_m": get["vacc"][ok],
            "speed_acc_mps": get["sacc"][ok],
            "fix_type": np.full(n, FixType.FIX_3D, dtype=np.int8),
        }
        has_bearing = fix.index(*_ALIASES["bearing"]) is not None
        nulls = {
            "vel_n_mps": np.full(n, not has_bearing) | ~np.isfinite(speed),
            "vel_e_mps": np.full(n, not has_bearing) | ~np.isfinite(speed),
            "vel_d_mps": np.ones(n, dtype=bool),
            "v_acc_m": ~np.isfinite(columns["v_acc_m"]),
            "speed_acc_mps": ~np.isfinite(columns["speed_acc_mps"]),
            "num_sats": np.ones(n, dtype=bool),
        }
        columns["num_sats"] = np.zeros(n, dtype=np.int16)
        lines = np.asarray(fix.lines, dtype=np.int64)[mask][ok]
        counters = {"no_time": int((~ok).sum())} if (~ok).any() else {}
        return Batch(
            f"Fix:{provider}", TableName.GNSS, columns, lines, nulls=nulls, counters=counters
        )

    def _imu_batch(self, acc: _Records, gyro: _Records, key: str) -> Batch:
        ta, tg = acc.floats("elapsedRealtimeNanos"), gyro.floats("elapsedRealtimeNanos")
        utc_a, utc_g = acc.floats("utcTimeMillis"), gyro.floats("utcTimeMillis")
        # fields are named after the record type: AccelXMps2, UncalGyroZRadPerSec ...
        a = np.stack([acc.floats(f"{acc.columns[0]}{ax}Mps2") for ax in "XYZ"], axis=1)
        g = np.stack([gyro.floats(f"{gyro.columns[0]}{ax}RadPerSec") for ax in "XYZ"], axis=1)
        offset = np.nanmedian(np.concatenate([utc_a * 1e6 - ta, utc_g * 1e6 - tg]))
        oa, og = np.argsort(ta, kind="stable"), np.argsort(tg, kind="stable")
        ta, a, tg, g = ta[oa], a[oa], tg[og], g[og]
        inside = (ta >= tg[0]) & (ta <= tg[-1])
        gi = np.stack([np.interp(ta[inside], tg, g[:, k]) for k in range(3)], axis=1)
        ai = a[inside]
        t = np.round(ta[inside] + offset).astype(np.int64)
        columns = {
            "t_ns": t,
            "acc_x_mps2": ai[:, 1],
            "acc_y_mps2": ai[:, 0],
            "acc_z_mps2": -ai[:, 2],
            "gyro_x_radps": gi[:, 1],
            "gyro_y_radps": gi[:, 0],
            "gyro_z_radps": -gi[:, 2],
        }
        lines = np.asarray(acc.lines, dtype=np.int64)[oa][inside]
        counters = {"accel_outside_gyro_span": int((~inside).sum())}
        info = {"time": f"elapsedRealtimeNanos + {offset * 1e-9:.3f} s (utcTimeMillis pairing)"}
        return Batch(key, TableName.IMU, columns, lines, counters=counters, info=info)


_USED = {"Raw", "Fix", "Accel", "Gyro", "UncalAccel", "UncalGyro"}


def _raw_columns(raw: _Records) -> RawColumns:
    full_bias, present = raw.ints("FullBiasNanos")
    return RawColumns(
        time_nanos=raw.ints("TimeNanos")[0],
        full_bias_nanos=full_bias,
        full_bias_present=present,
        bias_nanos=raw.floats("BiasNanos"),
        time_offset_nanos=raw.floats("TimeOffsetNanos"),
        received_sv_time_nanos=raw.ints("ReceivedSvTimeNanos")[0],
        received_sv_time_unc_nanos=raw.floats("ReceivedSvTimeUncertaintyNanos"),
        state=raw.ints("State")[0],
        svid=raw.ints("Svid")[0],
        constellation=_constellation(raw),
        carrier_hz=raw.floats("CarrierFrequencyHz"),
        cn0_dbhz=raw.floats("Cn0DbHz"),
        prr_mps=raw.floats("PseudorangeRateMetersPerSecond"),
        prr_unc_mps=raw.floats("PseudorangeRateUncertaintyMetersPerSecond"),
    )


def _constellation(raw: _Records) -> I64:
    values, present = raw.ints("ConstellationType")
    return np.where(present, values, 1)  # very early logs were GPS-only and had no column
