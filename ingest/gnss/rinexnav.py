"""RINEX 2 and 3 navigation files -> GPS broadcast ephemerides
(``ingest.gnss.ephemeris.Ephemeris``).

Parsing is georinex's. Before handing it the text, ``read_nav`` walks the records itself so
that damage is reported with line numbers (georinex reports none) and never aborts the file:

- a record whose fields do not parse as numbers is skipped (``bad_data_skipped``, its line);
- a last record cut short by the end of the file is dropped (``truncated``, its line);
- records of systems without an orbit model here (GLONASS, Galileo, BeiDou ... only GPS
  LNAV is implemented in ``ingest.gnss.ephemeris``) are counted per system and left out.

GPS week (catalogue case 35): the week of ``toe`` is taken from the record's own epoch
(``toc``, a calendar date), choosing the week that puts ``toe`` nearest ``toc``. A broadcast
week field that differs from it by a multiple of 1024 (a receiver that wrote the 10-bit
week) is corrected and counted; one that differs otherwise is counted as inconsistent.

The header's Klobuchar coefficients (``ION ALPHA``/``ION BETA``, ``IONOSPHERIC CORR GPSA/
GPSB``) and ``LEAP SECONDS`` are returned with the ephemerides.
"""

from __future__ import annotations

import io
import warnings
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from navreplay.ingest.damage import Completeness, DamageLog, Defect
from navreplay.ingest.errors import CorruptLogError
from navreplay.ingest.gnss.ephemeris import Ephemeris, concat
from navreplay.ingest.gnss.rinextext import Header, open_lines, read_header
from navreplay.ingest.gpstime import GPS_EPOCH, NS_PER_S, NS_PER_WEEK

#: Ephemeris field -> georinex variable (also the tests' reading of a file through georinex)
GEORINEX_FIELDS = {
    "af0_s": "SVclockBias",
    "af1_sps": "SVclockDrift",
    "af2_sps2": "SVclockDriftRate",
    "tgd_s": "TGD",
    "sqrt_a_sqrtm": "sqrtA",
    "e": "Eccentricity",
    "i0_rad": "Io",
    "idot_radps": "IDOT",
    "omega0_rad": "Omega0",
    "omega_dot_radps": "OmegaDot",
    "arg_perigee_rad": "omega",
    "m0_rad": "M0",
    "delta_n_radps": "DeltaN",
    "cuc_rad": "Cuc",
    "cus_rad": "Cus",
    "crc_m": "Crc",
    "crs_m": "Crs",
    "cic_rad": "Cic",
    "cis_rad": "Cis",
    "iode": "IODE",
    "iodc": "IODC",
    "health": "health",
    "accuracy_m": "SVacc",
    "transmit_sow_s": "TransTime",
}
_GPS_LINES = 8  # an LNAV record: the epoch line and 7 broadcast orbit lines
_SYSTEMS = {"G": "GPS", "R": "GLONASS", "E": "Galileo", "C": "BeiDou", "J": "QZSS", "I": "NavIC"}
_SYSTEMS["S"] = "SBAS"


@dataclass
class NavData:
    """GPS ephemerides of one or more navigation files, and what else they said.

    Attributes:
        ephemeris: the GPS LNAV records (healthy or not; ``ingest.gnss.ephemeris.select`` decides).
        klobuchar: (alpha, beta) GPS ionospheric coefficients, or None.
        leap_seconds: header LEAP SECONDS, or None.
        records: records read per system name (``GPS``, ``GLONASS`` ...).
        week_rollover_fixed: GPS records whose 10-bit week was corrected.
        week_inconsistent: GPS records whose week contradicted their epoch.
    """

    ephemeris: Ephemeris
    klobuchar: tuple[tuple[float, float, float, float], tuple[float, float, float, float]] | None
    leap_seconds: int | None
    records: dict[str, int] = field(default_factory=dict)
    week_rollover_fixed: int = 0
    week_inconsistent: int = 0


def read_nav(path: Path, variant: str, damage: DamageLog) -> NavData:
    """Read the GPS ephemerides of a RINEX 2/3 navigation file (see the module docstring).

    The result is cached per file (path, size, modification time), because an ingest reads
    a navigation file twice (its own inventory, and the observation files that use it);
    the defects found are recorded into ``damage`` on every call.

    Raises:
        UnsupportedFormatError, CorruptLogError: not a readable RINEX navigation file (named
            with the line), or under ``--strict`` any skipped record.
    """
    stat = path.stat()
    key = (str(path.resolve()), stat.st_size, stat.st_mtime_ns, variant)
    cached = _CACHE.get(key)
    if cached is None:
        found = Unreported(path)
        cached = (_read_nav(path, variant, found), found.defects)
        _CACHE[key] = cached
        while len(_CACHE) > _CACHE_SIZE:
            _CACHE.pop(next(iter(_CACHE)))
    damage.offsets_are_lines = True
    for defect in cached[1]:
        damage.record(defect)
    return cached[0]


class Unreported(DamageLog):
    """Collects the defects of a pass whose defects are reported elsewhere (no log, never
    strict)."""

    def __init__(self, path: Path) -> None:
        super().__init__(path, strict=False)

    def record(self, defect: Defect) -> None:
        self.defects.append(defect)


_CACHE: dict[tuple[str, int, int, str], tuple[NavData, list[Defect]]] = {}
_CACHE_SIZE = 8


def _read_nav(path: Path, variant: str, damage: DamageLog) -> NavData:
    with open_lines(path, variant) as lines:
        head = read_header(path, lines)
        if head.kind not in "NGHL":
            raise CorruptLogError(
                f"not a navigation file (RINEX type {head.kind!r})", path=path, record="line 1"
            )
        gps_text, records = _gps_records(head, lines, damage)
    klob = (head.iono_alpha, head.iono_beta)
    nav = NavData(
        _empty() if not gps_text else _georinex(path, gps_text),
        klob if klob[0] is not None and klob[1] is not None else None,  # type: ignore[arg-type]
        head.leap_seconds,
        records,
    )
    if len(nav.ephemeris):
        nav.ephemeris, nav.week_rollover_fixed, nav.week_inconsistent = _weeks(nav.ephemeris)
    return nav


def merge(navs: list[NavData]) -> NavData:
    """The ephemerides of several files as one (identical records kept once)."""
    eph = concat([n.ephemeris for n in navs]) if navs else _empty()
    if len(eph):
        key = np.stack([eph.prn, eph.toe_ns, eph.toc_ns, eph.iode], axis=1)
        _, first = np.unique(key, axis=0, return_index=True)
        eph = eph.take(np.sort(first))
    records: dict[str, int] = {}
    for n in navs:
        for k, v in n.records.items():
            records[k] = records.get(k, 0) + v
    return NavData(
        eph,
        next((n.klobuchar for n in navs if n.klobuchar is not None), None),
        next((n.leap_seconds for n in navs if n.leap_seconds is not None), None),
        records,
        sum(n.week_rollover_fixed for n in navs),
        sum(n.week_inconsistent for n in navs),
    )


def _record_start(head: Header, line: str) -> str | None:
    """The system letter if ``line`` starts a record, else None."""
    if head.version >= 3.0:
        if line[:1] in _SYSTEMS and line[1:3].strip().isdigit():
            return line[0]
        return None
    return head.system if line[:2].strip().isdigit() and line[2:3] == " " else None


def _fields_ok(head: Header, line: str, first: bool) -> bool:
    if first:
        start = 23 if head.version >= 3.0 else 22
        try:
            if head.version >= 3.0:
                [int(x) for x in line[4:23].split()]
            else:
                [float(x) for x in line[2:22].split()]
        except ValueError:
            return False
    else:
        start = 4 if head.version >= 3.0 else 3
    for k in range(4):
        text = line[start + 19 * k : start + 19 * (k + 1)].strip()
        if text:
            try:
                float(text.replace("D", "E").replace("d", "E"))
            except ValueError:
                return False
    return True


def _gps_records(
    head: Header, lines: Iterator[str], damage: DamageLog
) -> tuple[str, dict[str, int]]:
    """The header and the well-formed GPS records as text; records counted per system."""
    damage.offsets_are_lines = True
    out: list[str] = []
    records: dict[str, int] = {}
    current: list[str] = []
    sys_now: str | None = None
    start_line = 0
    number = head.lines

    def close(final: bool) -> None:
        if sys_now is None:
            return
        if sys_now == "G" and len(current) < _GPS_LINES:
            kind = Completeness.TRUNCATED if final else Completeness.BAD_DATA_SKIPPED
            damage.record(
                Defect(
                    kind,
                    f"GPS navigation record at line {start_line} has {len(current)} of "
                    f"{_GPS_LINES} lines: dropped",
                    offset=start_line,
                )
            )
            return
        name = _SYSTEMS[sys_now]
        records[name] = records.get(name, 0) + 1
        if sys_now == "G":
            out.extend(current[:_GPS_LINES])

    for raw in lines:
        number += 1
        line = raw.rstrip("\r\n")
        if not line.strip():
            continue
        system = _record_start(head, line)
        if system is not None:
            close(final=False)
            sys_now, current, start_line = system, [line], number
            if not _fields_ok(head, line, first=True):
                _bad(damage, number, "epoch line")
                sys_now = None
            continue
        if sys_now is None:
            continue  # continuation of a skipped record, or stray text
        if not _fields_ok(head, line, first=False):
            _bad(damage, number, "orbit line")
            sys_now = None
            continue
        current.append(line)
    close(final=True)
    if not out:
        return "", records
    return _header_text(head) + "\n".join(out) + "\n", records


def _bad(damage: DamageLog, line: int, what: str) -> None:
    damage.record(
        Defect(
            Completeness.BAD_DATA_SKIPPED,
            f"navigation record with an unreadable {what} at line {line}: skipped",
            offset=line,
        )
    )


def _header_text(head: Header) -> str:
    """A minimal header georinex accepts for the GPS records."""
    if head.version >= 3.0:
        first = f"{head.version:9.2f}{'':11}{'N: GNSS NAV DATA':<20}{'G: GPS':<20}"
    else:
        first = f"{head.version:9.2f}{'':11}{'N: GPS NAV DATA':<20}{'':20}"
    return f"{first}RINEX VERSION / TYPE\n{'':60}END OF HEADER\n"


def _georinex(path: Path, text: str) -> Ephemeris:
    import georinex

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", FutureWarning)  # georinex vs newer xarray
            ds = georinex.load(io.StringIO(text))
    except Exception as err:  # georinex raises bare ValueError/KeyError/IndexError...
        raise CorruptLogError(
            f"georinex cannot parse the GPS navigation records: {err}", path=path
        ) from err
    mask = np.isfinite(ds["sqrtA"].values)
    ti, si = np.nonzero(mask)
    cols: dict[str, np.ndarray] = {}
    for ours, theirs in GEORINEX_FIELDS.items():
        cols[ours] = ds[theirs].values[ti, si]
    fit = ds["FitIntvl"].values[ti, si] if "FitIntvl" in ds else np.zeros(ti.size)
    cols["fit_interval_h"] = np.nan_to_num(fit)
    cols["prn"] = np.array([int(str(s)[1:]) for s in ds["sv"].values[si]], dtype=np.int64)
    toc = (ds["time"].values[ti] - GPS_EPOCH).astype("timedelta64[ns]").astype(np.int64)
    cols["toc_ns"] = toc
    week = ds["GPSWeek"].values[ti, si]
    toe_s = ds["Toe"].values[ti, si]
    # the broadcast week for now; _weeks() checks it against toc
    cols["toe_ns"] = np.round(week).astype(np.int64) * NS_PER_WEEK + np.round(
        toe_s * NS_PER_S
    ).astype(np.int64)
    order = np.lexsort((cols["prn"], toc))
    return Ephemeris.from_columns(**{k: np.asarray(v)[order] for k, v in cols.items()})


def _weeks(eph: Ephemeris) -> tuple[Ephemeris, int, int]:
    """toe's week from toc (see the module docstring); counts of corrected and inconsistent."""
    toe_sow_ns = eph.toe_ns % NS_PER_WEEK
    file_week = eph.toe_ns // NS_PER_WEEK
    toc_week = eph.toc_ns // NS_PER_WEEK
    cand = (toc_week[:, None] + np.array([-1, 0, 1])) * NS_PER_WEEK + toe_sow_ns[:, None]
    best = cand[np.arange(len(eph)), np.argmin(np.abs(cand - eph.toc_ns[:, None]), axis=1)]
    week = best // NS_PER_WEEK
    differs = week != file_week
    rollover = differs & ((week - file_week) % 1024 == 0)
    fixed = Ephemeris(**{**eph._asdict(), "toe_ns": best})
    return fixed, int(rollover.sum()), int((differs & ~rollover).sum())


def _empty() -> Ephemeris:
    return Ephemeris.from_columns(**{name: np.empty(0) for name in Ephemeris._fields})
