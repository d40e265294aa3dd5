"""Google Smartphone Decimeter Challenge CSVs: measurements -> ``gnss_obs``, ground truth ->
``truth``.

Recognised by their header (``ingest.detect``): ``*_derived.csv`` (2021) and
``device_gnss.csv`` (2022) carry satellite states and corrections and map onto ``gnss_obs``
without an ephemeris (``ingest.gnss.gsdc``); the ground-truth files map onto ``truth``:

- 2021 ``*_ground_truth.csv``: ``millisSinceGpsEpoch`` (GPS time), ``latDeg``, ``lngDeg``,
  ``heightAboveWgs84EllipsoidM`` less 61 m, ``speedMps`` and ``courseDegree`` (velocity
  north/east from speed and course; vertical velocity and attitude not provided). The 61 m
  is the competition hosts' published correction of that column (gnss_lib_py applies it
  too); measured here: positions solved from ``Pixel4_derived.csv`` lie 59 m below the
  uncorrected truth and 0.6 m below the corrected one;
- 2022 ``ground_truth.csv``: ``UnixTimeMillis`` (UTC), ``LatitudeDegrees``,
  ``LongitudeDegrees``, ``AltitudeMeters``, ``SpeedMps``, ``BearingDegrees``.

Parsing is pyarrow's CSV reader. A row with the wrong number of fields is skipped
(``bad_data_skipped``, its line); a last line without its newline is dropped (``truncated``).
"""

from __future__ import annotations

import io
from collections.abc import Iterator, Sequence
from typing import Any

import numpy as np
import pyarrow as pa
import pyarrow.csv as pacsv

from navreplay.ingest.damage import Completeness, Defect
from navreplay.ingest.detect import Detected, Format
from navreplay.ingest.errors import CorruptLogError
from navreplay.ingest.gnss import gsdc
from navreplay.ingest.readers.base import (
    Batch,
    Inventory,
    LogReader,
    ReadContext,
    Selection,
    StreamInfo,
    selected_tables,
)
from navreplay.ingest.schema import TableName
from navreplay.ingest.timebase import TimeBase

_MEASUREMENTS = {"derived2021", "device_gnss2022"}
GSDC2021_HEIGHT_ERROR_M = 61.0
_KEYS = {
    "derived2021": "gsdc:derived",
    "device_gnss2022": "gsdc:device_gnss",
    "truth2021": "gsdc:ground_truth",
    "truth2022": "gsdc:ground_truth",
}


#: columns each variant cannot do without (the others read as NaN when absent)
_NEEDED = {
    "derived2021": ("millisSinceGpsEpoch", "signalType", "svid", "constellationType"),
    "device_gnss2022": ("TimeNanos", "FullBiasNanos", "SignalType", "Svid", "ConstellationType"),
    "truth2021": ("millisSinceGpsEpoch", "latDeg", "lngDeg"),
    "truth2022": ("UnixTimeMillis", "LatitudeDegrees", "LongitudeDegrees"),
}


class GsdcReader(LogReader):
    """One GSDC CSV file (see the module docstring)."""

    format = Format.GSDC
    offsets_are_lines = True

    def __init__(self, detected: Detected, ctx: ReadContext) -> None:
        super().__init__(detected, ctx)
        self.variant = detected.variant
        self.key = _KEYS[self.variant]
        self._table: pa.Table | None = None
        self._lines: np.ndarray | None = None

    def _read(self) -> pa.Table:
        if self._table is not None:
            return self._table
        data = self.path.read_bytes()
        if data and not data.endswith(b"\n"):
            cut = data.rfind(b"\n") + 1
            number = data[:cut].count(b"\n") + 1
            self.damage.record(
                Defect(
                    Completeness.TRUNCATED,
                    f"the last line ({number}) is cut short: dropped",
                    offset=number,
                )
            )
            data = data[:cut]
        data, repeats = _blank_repeated_headers(data)
        if repeats:
            self.damage.count("repeated_header_lines", len(repeats))
            self.damage.note(f"repeated header lines skipped at lines {repeats[:10]}")
        skipped: list[int] = []

        def bad_row(row: pacsv.InvalidRow) -> str:
            skipped.append(int(row.number) if row.number is not None else -1)
            return "skip"

        types = {c: pa.string() for c in ("SignalType", "signalType", "CodeType")}
        types |= {c: pa.int64() for c in ("FullBiasNanos", "TimeNanos", "millisSinceGpsEpoch")}
        try:
            table = pacsv.read_csv(
                io.BytesIO(data),
                parse_options=pacsv.ParseOptions(invalid_row_handler=bad_row),
                convert_options=pacsv.ConvertOptions(column_types=types, strings_can_be_null=True),
            )
        except pa.ArrowInvalid as err:
            raise CorruptLogError(f"unreadable CSV: {err}", path=self.path) from err
        for number in skipped:
            self.damage.record(
                Defect(
                    Completeness.BAD_DATA_SKIPPED,
                    f"row at line {number} has the wrong number of fields: skipped",
                    offset=number,
                )
            )
        lines = np.arange(2, table.num_rows + 2, dtype=np.int64)
        if skipped:  # line numbers of the rows kept (the header is line 1)
            good = np.setdiff1d(np.arange(2, table.num_rows + len(skipped) + 2), skipped)
            lines = good[: table.num_rows].astype(np.int64)
        if repeats:  # the blanked header lines are not rows: later rows sit lower in the file
            lines = lines + np.searchsorted(np.asarray(repeats), lines, side="right")
        missing = [c for c in _NEEDED[self.variant] if c not in table.column_names]
        if missing:
            raise CorruptLogError(
                f"the header lacks column(s) {', '.join(missing)} of a GSDC {self.variant} file",
                path=self.path,
                offset=1,
                record="line 1",
                hint="the header line is damaged or the file is not a GSDC CSV; repair it",
            )
        _check_numbers(table, lines, set(types), self.path)
        self._table, self._lines = table, lines
        return table

    # ---------------------------------------------------------------------------- inventory
    def inventory(self) -> Inventory:
        table = self._read()
        t, base = self._times(table)
        measurements = self.variant in _MEASUREMENTS
        stream = StreamInfo(
            key=self.key,
            msgtype=f"GSDC {self.variant}",
            count=table.num_rows,
            start_ns=int(t.min()) if t.size else None,
            end_ns=int(t.max()) if t.size else None,
            table=TableName.GNSS_OBS if measurements else TableName.TRUTH,
            time_base=base,
            detail=f"{np.unique(t).size} epochs" if measurements else "ground truth",
        )
        return Inventory(self.path, self.format, (stream,))

    def _times(self, table: pa.Table) -> tuple[np.ndarray, TimeBase]:
        if self.variant == "derived2021":
            millis = _i64(table, "millisSinceGpsEpoch")
            t, _ = gsdc.restamp_2021(
                millis, _f(table, "receivedSvTimeInGpsNanos"), _f(table, "rawPrM")
            )
            return t, TimeBase.GPS
        if self.variant == "truth2021":
            return _i64(table, "millisSinceGpsEpoch") * 1_000_000, TimeBase.GPS
        if self.variant == "truth2022":
            return _i64(table, "UnixTimeMillis") * 1_000_000, TimeBase.UTC
        bias = np.round(np.nan_to_num(_f(table, "BiasNanos"))).astype(np.int64)
        return _i64(table, "TimeNanos") - _i64(table, "FullBiasNanos") - bias, TimeBase.GPS

    # --------------------------------------------------------------------------------- read
    def read(self, selections: Sequence[Selection]) -> Iterator[Batch]:
        if self.key not in selected_tables(selections):
            return
        table = self._read()
        assert self._lines is not None
        t, _ = self._times(table)
        if self.variant in _MEASUREMENTS:
            yield self._obs_batch(table, t)
        else:
            yield self._truth_batch(table, t)

    def _obs_batch(self, table: pa.Table, t: np.ndarray) -> Batch:
        sig = _signals(table, t, self.variant)
        rows, excluded = gsdc.select(sig)
        columns, nulls, solved = gsdc.columns(sig, rows)
        counters = {f"excluded_{k}": v for k, v in excluded.items()}
        info = {"source": "GSDC satellite states and corrections (no ephemeris)"}
        if self.variant == "derived2021":
            _, shift = gsdc.restamp_2021(
                _i64(table, "millisSinceGpsEpoch"),
                _f(table, "receivedSvTimeInGpsNanos"),
                _f(table, "rawPrM"),
            )
            counters["epochs_restamped"] = int(np.unique(t[shift != 0]).size)
            info["time"] = "millisSinceGpsEpoch moved back by the lateness its measurements show"
            counters["epochs_receiver_solved"] = solved
        assert self._lines is not None
        return Batch(
            self.key,
            TableName.GNSS_OBS,
            columns,
            self._lines[rows],
            nulls=nulls,
            counters=counters,
            info=info,
        )

    def _truth_batch(self, table: pa.Table, t: np.ndarray) -> Batch:
        v2021 = self.variant == "truth2021"
        names = (
            ("latDeg", "lngDeg", "heightAboveWgs84EllipsoidM", "speedMps", "courseDegree")
            if v2021
            else (
                "LatitudeDegrees",
                "LongitudeDegrees",
                "AltitudeMeters",
                "SpeedMps",
                "BearingDegrees",
            )
        )
        lat, lon, alt, speed, course = (_f(table, c) for c in names)
        if v2021:
            alt = alt - GSDC2021_HEIGHT_ERROR_M
        n = t.size
        columns = {
            "t_ns": t,
            "lat_deg": lat,
            "lon_deg": lon,
            "alt_m": alt,
            "vel_n_mps": speed * np.cos(np.radians(course)),
            "vel_e_mps": speed * np.sin(np.radians(course)),
        }
        none = np.ones(n, dtype=bool)
        nulls = {"vel_d_mps": none, "roll_rad": none, "pitch_rad": none, "yaw_rad": none}
        for name in nulls:
            columns[name] = np.full(n, np.nan)
        assert self._lines is not None
        info = (
            {"height": f"heightAboveWgs84EllipsoidM - {GSDC2021_HEIGHT_ERROR_M:.0f} m"}
            if v2021
            else {}
        )
        return Batch(self.key, TableName.TRUTH, columns, self._lines, nulls=nulls, info=info)


def _f(table: pa.Table, name: str) -> np.ndarray:
    if name not in table.column_names:
        return np.full(table.num_rows, np.nan)
    col = table.column(name)
    return np.asarray(
        col.cast(pa.float64(), safe=False).to_numpy(zero_copy_only=False), dtype=np.float64
    )


def _i64(table: pa.Table, name: str) -> np.ndarray:
    col = table.column(name)
    if pa.types.is_floating(col.type):  # "1.27352946336306E+018": no better than a double
        return np.round(np.asarray(col.to_numpy(zero_copy_only=False))).astype(np.int64)
    return np.asarray(col.fill_null(0).to_numpy(zero_copy_only=False), dtype=np.int64)


def _signals(table: pa.Table, t: np.ndarray, variant: str) -> gsdc.Signals:
    if variant == "derived2021":
        c = {
            "con": "constellationType",
            "svid": "svid",
            "sig": "signalType",
            "pr": "rawPrM",
            "prs": "rawPrUncM",
            "isrb": "isrbM",
            "clk": "satClkBiasM",
            "drift": "satClkDriftMps",
            "iono": "ionoDelayM",
            "tropo": "tropoDelayM",
        }
        pos = [f"{a}SatPosM" for a in "xyz"]
        vel = [f"{a}SatVelMps" for a in "xyz"]
    else:
        c = {
            "con": "ConstellationType",
            "svid": "Svid",
            "sig": "SignalType",
            "pr": "RawPseudorangeMeters",
            "prs": "RawPseudorangeUncertaintyMeters",
            "isrb": "IsrbMeters",
            "clk": "SvClockBiasMeters",
            "drift": "SvClockDriftMetersPerSecond",
            "iono": "IonosphericDelayMeters",
            "tropo": "TroposphericDelayMeters",
        }
        pos = [f"SvPosition{a}EcefMeters" for a in "XYZ"]
        vel = [f"SvVelocity{a}EcefMetersPerSecond" for a in "XYZ"]
    signal = table.column(c["sig"]).fill_null("").to_numpy(zero_copy_only=False).astype(str)
    extra: dict[str, np.ndarray | None] = {}
    if variant == "device_gnss2022":
        extra = {
            "prr_mps": _f(table, "PseudorangeRateMetersPerSecond"),
            "prr_std_mps": _f(table, "PseudorangeRateUncertaintyMetersPerSecond"),
            "cn0_dbhz": _f(table, "Cn0DbHz"),
            "rx_ecef_m": np.stack([_f(table, f"WlsPosition{a}EcefMeters") for a in "XYZ"], 1),
        }
    return gsdc.Signals(
        t_ns=t,
        sv=gsdc.sv_ids(_i64(table, c["con"]), _i64(table, c["svid"])),
        signal=signal,
        raw_pr_m=_f(table, c["pr"]),
        raw_pr_std_m=_f(table, c["prs"]),
        isrb_m=np.nan_to_num(_f(table, c["isrb"])),
        sat_pos_m=np.stack([_f(table, p) for p in pos], axis=1),
        sat_vel_mps=np.stack([_f(table, v) for v in vel], axis=1),
        sat_clock_m=_f(table, c["clk"]),
        sat_clock_drift_mps=_f(table, c["drift"]),
        iono_m=_f(table, c["iono"]),
        tropo_m=_f(table, c["tropo"]),
        **extra,
    )


def _blank_repeated_headers(data: bytes) -> tuple[bytes, list[int]]:
    """``data`` with later copies of its header line emptied (a file concatenated with itself
    or a logger that restarted into it), and their line numbers."""
    header, sep, rest = data.partition(b"\n")
    if not sep or header.rstrip(b"\r") + b"\n" not in rest:
        return data, []
    lines = rest.split(b"\n")
    repeats = [i + 2 for i, ln in enumerate(lines) if ln.rstrip(b"\r") == header.rstrip(b"\r")]
    for i in repeats:
        lines[i - 2] = b""
    return header + sep + b"\n".join(lines), repeats


def _check_numbers(table: pa.Table, lines: np.ndarray, declared: set[str], path: Any) -> None:
    """A column read as text although most of its values are numbers (a numeric column with
    damaged lines in it, not a text column such as ``MessageType``) names its first bad line."""
    for name in table.column_names:
        col = table.column(name)
        if name in declared or not pa.types.is_string(col.type):
            continue
        values = col.to_pylist()
        bad = [i for i, v in enumerate(values) if v is not None and not _is_number(v)]
        if bad and len(bad) * 2 < sum(v is not None for v in values):
            i = bad[0]
            raise CorruptLogError(
                f"column {name!r} holds {str(values[i])[:40]!r}, not a number",
                path=path,
                offset=int(lines[i]),
                record=f"line {int(lines[i])}",
                hint="the line is damaged; remove or repair it",
            )


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True
