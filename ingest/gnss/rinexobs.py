"""RINEX 2 and 3 observation files -> rows of the GPS L1 C/A signal, in chunks of arrays.

Why not georinex here: georinex builds its xarray Dataset by concatenating one epoch at a
time, about 3.5 ms per epoch whatever the satellite count (measured 3.3-7 s for the
15-minute 1 Hz ``seoul_campus`` file and 12-24 s for one hour of 12 satellites on the 2-core
test machine; ``benchmarks/bench_rinex.py`` prints the ratio): a 10 Hz receiver logging for an
hour takes minutes, and it reports no line numbers. ``read_obs`` walks the epochs
(``ingest.gnss.rinexepochs``), keeps the GPS records as fixed-width byte rows and converts each
field column with one numpy cast, in chunks of ``CHUNK_ROWS`` rows: about 100x faster, with
every row's line number. ``from_georinex`` reads the same rows through georinex; the tests
hold the two equal, bit for bit, on every fixture (RINEX 2 and 3).

Signal: the GPS L1 pseudorange is the first of ``C1C, C1W, C1P, C1X, C1L, C1S`` (RINEX 3) or
``C1, P1`` (RINEX 2) in the header; Doppler and signal strength are the same signal's when
present (``D1C``/``S1C``, ``D1``/``S1``), else the first L1 ones. Rows of other systems are
counted per system. A blank field is NaN.

Time: epochs become GPS ``t_ns`` from the file's time system: ``GPS``, ``GAL``, ``QZS``,
``IRN`` as they are; ``BDT`` + 14 s; ``GLO`` (UTC(SU) + 3 h) through the leap-second table.
"""

from __future__ import annotations

import datetime as dt
import warnings
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import numpy.typing as npt

from navreplay.ingest.arrays import F64, I64
from navreplay.ingest.damage import Completeness, DamageLog, Defect
from navreplay.ingest.errors import CorruptLogError
from navreplay.ingest.gnss.rinexepochs import Counts, Epoch, epochs
from navreplay.ingest.gnss.rinextext import Header, open_lines, read_header
from navreplay.ingest.gpstime import GPS_EPOCH, GPS_EPOCH_UNIX_NS, NS_PER_S
from navreplay.ingest.timebase import utc_to_gps_ns

CHUNK_ROWS = 50_000
_GPS_EPOCH_ORDINAL = dt.date(1980, 1, 6).toordinal()
_CODES = {3: ("C1C", "C1W", "C1P", "C1X", "C1L", "C1S"), 2: ("C1", "P1")}
_GPS_LIKE = frozenset({"GPS", "GAL", "QZS", "IRN", ""})
_BDT_AHEAD_S = 14
SYSTEM_NAMES = {"G": "GPS", "R": "GLONASS", "E": "Galileo", "C": "BeiDou", "J": "QZSS"}
SYSTEM_NAMES |= {"I": "NavIC", "S": "SBAS"}


@dataclass(frozen=True)
class Signals:
    """The GPS observation codes read (``None`` when the file has none of that kind)."""

    pseudorange: str
    doppler: str | None
    strength: str | None


@dataclass
class ObsRows:
    """GPS rows of one chunk, epoch by epoch in file order.

    Attributes:
        t_ns: epoch, GPS time base; prn: GPS PRN; line: line number of the row's record.
        pseudorange_m, doppler_hz, strength: the signal's values (NaN where blank).
    """

    t_ns: I64
    prn: I64
    pseudorange_m: F64
    doppler_hz: F64
    strength: F64
    line: I64

    def __len__(self) -> int:
        return int(self.t_ns.size)


@dataclass
class ObsScan:
    """Counts of a pass over the body (complete once the rows have all been read)."""

    epochs: int = 0
    first_t_ns: int | None = None
    last_t_ns: int | None = None
    rows_by_system: dict[str, int] = field(default_factory=dict)
    skipped: Counts = field(default_factory=Counts)

    @property
    def gps_rows(self) -> int:
        return self.rows_by_system.get("GPS", 0)


def signals(path: Path, head: Header) -> Signals:
    """The GPS codes to read (see the module docstring).

    Raises:
        CorruptLogError: the header lists no GPS L1 pseudorange.
    """
    types = head.obs_types.get("G", [])
    order = _CODES[3 if head.version >= 3.0 else 2]
    code = next((c for c in order if c in types), None)
    if code is None:
        raise CorruptLogError(
            f"no GPS L1 pseudorange among the observation types ({' '.join(types) or 'none'}; "
            f"looked for {', '.join(order)})",
            path=path,
            record=f"line {head.lines}",
        )

    def partner(kind: str) -> str | None:
        same = kind + code[1:]
        return same if same in types else next((t for t in types if t[:2] == kind + "1"), None)

    return Signals(code, partner("D"), partner("S"))


def label_ns(label: tuple[int, int, int, int, int, str], system: str) -> int:
    """GPS ``t_ns`` of an epoch label written on ``system`` time (module docstring)."""
    year, month, day, hour, minute, sec = label
    whole, _, frac = sec.strip().partition(".")
    days = dt.date(year, month, day).toordinal() - _GPS_EPOCH_ORDINAL
    t = (days * 86_400 + hour * 3600 + minute * 60 + int(whole or 0)) * NS_PER_S
    t += int((frac + "000000000")[:9])
    return _on_gps(t, system)


def _on_gps(t_label_ns: int, system: str) -> int:
    if system in _GPS_LIKE:
        return t_label_ns
    if system == "BDT":
        return t_label_ns + _BDT_AHEAD_S * NS_PER_S
    if system == "GLO":  # a calendar label on the UTC(SU) + 3 h scale
        unix = t_label_ns + GPS_EPOCH_UNIX_NS - 3 * 3600 * NS_PER_S
        return int(utc_to_gps_ns(np.array([unix], dtype=np.int64))[0])
    raise ValueError(f"unknown RINEX time system {system!r}")


def read_obs(
    path: Path, variant: str, damage: DamageLog, *, chunk_rows: int = CHUNK_ROWS
) -> tuple[Header, Signals, ObsScan, Iterator[ObsRows]]:
    """Header, codes, counts and the chunks of GPS rows of an observation file.

    The file is opened again by the generator; the counts are complete once it is exhausted.

    Raises:
        UnsupportedFormatError, CorruptLogError: see ``ingest.gnss.rinextext.read_header``;
            ``signals``; and, under ``--strict``, any damage.
    """
    damage.offsets_are_lines = True
    with open_lines(path, variant) as lines:
        head = read_header(path, lines)
    sig = signals(path, head)
    if head.time_system not in _GPS_LIKE | {"BDT", "GLO"}:
        raise CorruptLogError(
            f"unknown time system {head.time_system!r} in TIME OF FIRST OBS",
            path=path,
            record=f"line {head.lines}",
        )
    scan = ObsScan()

    def chunks() -> Iterator[ObsRows]:
        acc = _Accumulator(head, sig, damage)
        with open_lines(path, variant) as body:
            for _ in range(head.lines):
                next(body)
            for epoch in epochs(head, body, damage, scan.skipped):
                t = label_ns(epoch.label, head.time_system)
                _count(scan, epoch, t)
                acc.add(epoch, t)
                if len(acc) >= chunk_rows:
                    yield acc.flush()
        if len(acc):
            yield acc.flush()

    return head, sig, scan, chunks()


def _count(scan: ObsScan, epoch: Epoch, t: int) -> None:
    scan.epochs += 1
    scan.first_t_ns = t if scan.first_t_ns is None else scan.first_t_ns
    scan.last_t_ns = t
    for sv, _, _ in epoch.sats:
        name = SYSTEM_NAMES.get(sv[:1], sv[:1])
        scan.rows_by_system[name] = scan.rows_by_system.get(name, 0) + 1


class _Accumulator:
    """GPS records as fixed-width byte rows until a chunk is converted at once."""

    def __init__(self, head: Header, sig: Signals, damage: DamageLog) -> None:
        types = head.obs_types.get("G", [])
        self.cols = [types.index(c) if c else -1 for c in (sig.pseudorange, sig.doppler)]
        self.cols.append(types.index(sig.strength) if sig.strength else -1)
        self.width = 16 * max(len(types), 1)
        self.damage = damage
        self._text: list[bytes] = []
        self._prn: list[str] = []
        self._line: list[int] = []
        self._t: list[int] = []

    def __len__(self) -> int:
        return len(self._t)

    def add(self, epoch: Epoch, t: int) -> None:
        w = self.width
        for sv, text, line in epoch.sats:
            if sv[:1] == "G":
                self._text.append(text[:w].ljust(w).encode("ascii", "replace"))
                self._prn.append(sv[1:])
                self._line.append(line)
                self._t.append(t)

    def flush(self) -> ObsRows:
        w = self.width
        buf = np.frombuffer(b"".join(self._text), np.uint8).reshape(-1, w)
        line = np.asarray(self._line, dtype=np.int64)
        prn = np.asarray(self._prn, dtype="S2").astype(np.int64)
        values = [
            self._column(buf[:, 16 * k : 16 * k + 14], line)
            if k >= 0
            else np.full(len(buf), np.nan)
            for k in self.cols
        ]
        t = np.asarray(self._t, dtype=np.int64)
        out = ObsRows(t, prn, values[0], values[1], values[2], line)
        self._text, self._prn, self._line, self._t = [], [], [], []
        return out

    def _column(self, raw: npt.NDArray[np.uint8], line: I64) -> F64:
        """F14.3 fields -> float64 with one cast; blanks are NaN, unreadable ones too
        (recorded with their line)."""
        raw = np.ascontiguousarray(raw)
        text = raw.view("S14")[:, 0].copy()
        blank = (raw == ord(" ")).all(axis=1)
        text[blank] = b"nan"
        try:
            return np.asarray(text.astype(np.float64), dtype=np.float64)
        except ValueError:
            out = np.empty(text.size)
            for i, value in enumerate(text.tolist()):
                try:
                    out[i] = float(value)
                except ValueError:
                    out[i] = np.nan
                    self.damage.record(
                        Defect(
                            Completeness.BAD_DATA_SKIPPED,
                            f"unreadable observation {value.decode(errors='replace')!r} at "
                            f"line {int(line[i])}: stored as NaN",
                            offset=int(line[i]),
                        )
                    )
            return out


def from_georinex(path: Path, head: Header, sig: Signals) -> ObsRows:
    """The same GPS rows through georinex (the reference the fast path is tested against;
    no line numbers: ``line`` is -1)."""
    import georinex

    codes = [c for c in (sig.pseudorange, sig.doppler, sig.strength) if c]
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", FutureWarning)  # georinex vs newer xarray
            ds = georinex.load(path, use={"G"}, meas=codes)
    except Exception as err:  # georinex raises bare ValueError/IndexError on bad text
        raise CorruptLogError(f"georinex cannot parse the observations: {err}", path=path) from err
    svs = np.array([str(s) for s in ds["sv"].values])
    gps = np.flatnonzero(np.char.startswith(svs, "G"))
    pr = ds[sig.pseudorange].values[:, gps]
    ti, si = np.nonzero(np.isfinite(pr))
    labels = (ds["time"].values.astype("datetime64[ns]") - GPS_EPOCH).astype(np.int64)
    t = np.array([_on_gps(int(x), head.time_system) for x in labels], dtype=np.int64)

    def values(code: str | None) -> F64:
        if code is None:
            return np.full(ti.size, np.nan)
        return np.asarray(ds[code].values[:, gps][ti, si], dtype=np.float64)

    prn = np.array([int(s[1:]) for s in svs[gps]], dtype=np.int64)[si]
    line = np.full(ti.size, -1, dtype=np.int64)
    return ObsRows(
        t[ti], prn, values(sig.pseudorange), values(sig.doppler), values(sig.strength), line
    )
