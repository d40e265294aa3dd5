"""RINEX files as text: opening (plain, gzip, Hatanaka), the header, and the errors they raise.

Shared by the observation and navigation modules (``ingest.gnss.rinexobs``,
``ingest.gnss.rinexnav``).
``open_lines`` yields the text lines of a RINEX file whatever its packing: gzip is streamed,
Hatanaka-compressed observations (CRINEX) are expanded with the ``hatanaka`` package (the
one georinex uses). ``read_header`` reads the header into a ``Header`` and refuses what
navreplay cannot read with an error naming the file and the line:

- a first line without ``RINEX VERSION / TYPE`` in columns 61-80;
- a version outside 2.x / 3.x (RINEX 4 navigation messages are a different record layout);
- a header without ``END OF HEADER`` (a truncated or non-RINEX file);
- for observations: no ``SYS / # / OBS TYPES`` (3.x) or ``# / TYPES OF OBSERV`` (2.x).

Line numbers are 1-based, in the expanded text (for CRINEX they are those of the RINEX
text that the Hatanaka expansion gives).
"""

from __future__ import annotations

import gzip
import io
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

from navreplay.ingest.errors import CorruptLogError, UnsupportedFormatError

MAX_HEADER_LINES = 5000


@dataclass
class Header:
    """What navreplay uses from a RINEX header.

    Attributes:
        version: e.g. 3.04 or 2.11.
        kind: ``O`` observation, ``N``/``G``/``H``/``L`` navigation (RINEX 2 letters; RINEX 3
            navigation files are ``N`` with a system).
        system: satellite system letter of the file (``G``, ``R``, ``E``, ``M`` mixed ...).
        lines: number of header lines (the body starts at line ``lines + 1``).
        obs_types: observation codes per system (``{"G": ["C1C", "D1C", "S1C"]}``); for RINEX
            2 the single list is stored under every system letter it applies to.
        approx_ecef_m: APPROX POSITION XYZ, or None.
        leap_seconds: LEAP SECONDS, or None.
        time_system: from TIME OF FIRST OBS (``GPS``, ``GLO``, ``GAL``, ``BDT`` ...).
        clock_offset_applied: RCV CLOCK OFFS APPL is 1.
        iono_alpha, iono_beta: GPS Klobuchar coefficients (ION ALPHA/BETA, IONOSPHERIC CORR).
        signal_strength_unit: SIGNAL STRENGTH UNIT (``DBHZ``), or "".
    """

    version: float
    kind: str
    system: str
    lines: int = 0
    obs_types: dict[str, list[str]] = field(default_factory=dict)
    approx_ecef_m: tuple[float, float, float] | None = None
    leap_seconds: int | None = None
    time_system: str = "GPS"
    clock_offset_applied: bool = False
    iono_alpha: tuple[float, float, float, float] | None = None
    iono_beta: tuple[float, float, float, float] | None = None
    signal_strength_unit: str = ""


@contextmanager
def open_lines(path: Path, variant: str) -> Iterator[Iterator[str]]:
    """The file's text lines (newline kept), whatever the packing named by ``variant``."""
    try:
        if variant.startswith("crinex") or variant.endswith("+crinex"):
            import hatanaka

            text = hatanaka.decompress(path).decode("ascii", "replace")
            yield iter(io.StringIO(text))
        elif variant.endswith("+gzip"):
            with gzip.open(path, "rt", encoding="ascii", errors="replace", newline="") as fh:
                yield iter(fh)
        else:
            with path.open("r", encoding="ascii", errors="replace", newline="") as fh:
                yield iter(fh)
    except (OSError, EOFError, ValueError) as err:
        raise CorruptLogError(f"cannot read the RINEX text: {err}", path=path) from err


def _num(text: str) -> float:
    return float(text.strip().replace("D", "E").replace("d", "E"))


def read_header(path: Path, lines: Iterator[str]) -> Header:
    """Read the header from ``lines`` (consumed up to END OF HEADER).

    Raises:
        UnsupportedFormatError: not RINEX, or a version navreplay does not read.
        CorruptLogError: no END OF HEADER, or a malformed header line (named by number).
    """
    first = next(lines, "").rstrip("\r\n")
    if first[60:80].strip() not in ("RINEX VERSION / TYPE", "CRINEX VERS   / TYPE"):
        raise UnsupportedFormatError(
            "not a RINEX file: line 1 has no 'RINEX VERSION / TYPE' label in columns 61-80",
            path=path,
            record="line 1",
        )
    try:
        version = float(first[:9])
    except ValueError as err:
        raise CorruptLogError(
            f"unreadable RINEX version {first[:9]!r}", path=path, record="line 1"
        ) from err
    if not 2.0 <= version < 4.0:
        raise UnsupportedFormatError(
            f"RINEX version {version:.2f} is not supported (2.x and 3.x are)",
            path=path,
            record="line 1",
            hint="convert it to RINEX 3 (e.g. with gfzrnx) first",
        )
    kind = first[20:21].upper()
    system = first[40:41].upper() or "G"
    if version < 3.0 and kind in "GHL":
        system = {"G": "R", "H": "S", "L": "E"}[kind]
    elif version < 3.0 and kind == "N":
        system = "G"
    head = Header(version, kind, system.strip() or "G")
    pending: _Pending = None  # observation types still being continued
    for number, raw in enumerate(lines, start=2):
        line = raw.rstrip("\r\n")
        label = line[60:80].strip()
        try:
            pending = _header_line(head, line, label, pending)
        except (ValueError, IndexError) as err:
            raise CorruptLogError(
                f"malformed header line {label!r}: {err}", path=path, record=f"line {number}"
            ) from err
        if label == "END OF HEADER":
            head.lines = number
            break
        if number > MAX_HEADER_LINES:
            break
    else:
        number = 0
    if head.lines == 0:
        raise CorruptLogError(
            "no END OF HEADER line: the file is truncated inside its header or is not RINEX",
            path=path,
            record=f"line {number}" if number else None,
        )
    if head.kind == "O" and not head.obs_types:
        raise CorruptLogError(
            "observation header without observation types (SYS / # / OBS TYPES or "
            "# / TYPES OF OBSERV)",
            path=path,
            record=f"line {head.lines}",
        )
    return head


_Pending = tuple[str, int, list[str]] | None


def _header_line(head: Header, line: str, label: str, pending: _Pending) -> _Pending:
    """Apply one header line; returns the observation-type list still being continued."""
    if label == "SYS / # / OBS TYPES":
        return _obs_types(head, line, pending, line[0:1].strip(), (3, 6), 7)
    if label == "# / TYPES OF OBSERV":
        return _obs_types(head, line, pending, "*" if line[:6].strip() else "", (0, 6), 6)
    handler = _SIMPLE.get(label)
    if handler is not None:
        handler(head, line)
    return pending


def _obs_types(
    head: Header, line: str, pending: _Pending, sys: str, count: tuple[int, int], codes_at: int
) -> _Pending:
    """``SYS / # / OBS TYPES`` (3.x, per system) or ``# / TYPES OF OBSERV`` (2.x, for all
    systems), both continued on further lines when long."""
    codes = line[codes_at:60].split()
    if sys:
        pending = (sys, int(line[count[0] : count[1]]), codes)
    elif pending is not None:
        pending[2].extend(codes)
    if pending is None:
        return None
    for letter in "GRESJCI" if pending[0] == "*" else pending[0]:
        head.obs_types[letter] = pending[2]
    return pending if len(pending[2]) < pending[1] else None


def _approx(head: Header, line: str) -> None:
    x, y, z = (_num(line[k : k + 14]) for k in (0, 14, 28))
    head.approx_ecef_m = (x, y, z)


def _leap(head: Header, line: str) -> None:
    head.leap_seconds = int(line[:6])


def _first_obs(head: Header, line: str) -> None:
    head.time_system = line[48:51].strip() or head.time_system


def _clock_applied(head: Header, line: str) -> None:
    head.clock_offset_applied = line[:6].strip() == "1"


def _strength(head: Header, line: str) -> None:
    head.signal_strength_unit = line[:20].strip()


def _iono(which: str, start: int) -> Callable[[Header, str], None]:
    def apply(head: Header, line: str) -> None:
        if start == 5 and line[:4] not in ("GPSA", "GPSB"):
            return
        kind = which or ("alpha" if line[:4] == "GPSA" else "beta")
        a, b, c, d = (_num(line[start + 12 * k : start + 12 * (k + 1)]) for k in range(4))
        setattr(head, f"iono_{kind}", (a, b, c, d))

    return apply


_SIMPLE: dict[str, Callable[[Header, str], None]] = {
    "APPROX POSITION XYZ": _approx,
    "LEAP SECONDS": _leap,
    "TIME OF FIRST OBS": _first_obs,
    "RCV CLOCK OFFS APPL": _clock_applied,
    "SIGNAL STRENGTH UNIT": _strength,
    "ION ALPHA": _iono("alpha", 2),
    "ION BETA": _iono("beta", 2),
    "IONOSPHERIC CORR": _iono("", 5),
}
