"""NMEA 0183 sentences -> epochs: checksums, field decoding, and the grouping of one receiver
output cycle (RMC, VTG, GGA, GSA, GSV, GST, GLL ...) into one ``Epoch``.

Only what navreplay uses is decoded:

===  ===========================================================================================
GGA  time of day, lat/lon (ddmm.mmmm), quality, satellites used (often capped at 12), HDOP,
     altitude above mean sea level + geoid separation (their sum is the ellipsoidal height)
RMC  time of day, status, speed (knots), course (deg true), date (ddmmyy)
VTG  course (deg true), speed (km/h)
GSA  navigation mode (2-D/3-D), satellites used (one sentence per system), PDOP, HDOP, VDOP
GSV  satellites in view (elevation, azimuth, C/N0), one group per system and signal
GST  1-sigma latitude, longitude and altitude errors (m)
ZDA  time of day and full date
===  ===========================================================================================

A sentence is ``$<talker><type>,<fields>*<hh>``; a sentence whose checksum does not match, that
has none, or that does not start with ``$`` is rejected with its line number (the caller
counts it). Fields that are empty decode to NaN.

An epoch begins at the first sentence carrying a time of day different from the current one;
sentences without a time (VTG, GSA, GSV) belong to the epoch in progress.
"""

from __future__ import annotations

import math
import operator
from dataclasses import dataclass, field
from functools import reduce

KNOT_MPS = 1852.0 / 3600.0


def checksum_ok(line: bytes) -> bool | None:
    """True/False for a sentence with a checksum, None when it has none or is not a sentence."""
    if not line.startswith(b"$"):
        return None
    body, star, given = line[1:].rpartition(b"*")
    if not star or len(given) != 2:
        return None
    try:
        expected = int(given, 16)
    except ValueError:
        return False
    return reduce(operator.xor, body, 0) == expected


def num(text: str) -> float:
    """A decimal field, NaN when empty or not a number."""
    try:
        return float(text) if text else math.nan
    except ValueError:
        return math.nan


def time_of_day_s(text: str) -> float:
    """``hhmmss.ss`` -> seconds since midnight (NaN when malformed)."""
    if len(text) < 6 or not text[:6].isdigit():
        return math.nan
    return int(text[:2]) * 3600 + int(text[2:4]) * 60 + num(text[4:])


def degrees(value: str, hemisphere: str) -> float:
    """``ddmm.mmmm``/``dddmm.mmmm`` plus hemisphere -> signed decimal degrees (NaN if empty)."""
    v = num(value)
    if math.isnan(v):
        return v
    deg = math.floor(v / 100.0)
    out = deg + (v - 100.0 * deg) / 60.0
    return -out if hemisphere in ("S", "W") else out


def date_ymd(ddmmyy: str) -> tuple[int, int, int] | None:
    """RMC ``ddmmyy`` -> (year, month, day); two-digit years 80-99 are 19xx, else 20xx."""
    if len(ddmmyy) != 6 or not ddmmyy.isdigit():
        return None
    yy = int(ddmmyy[4:])
    return (1900 + yy if yy >= 80 else 2000 + yy, int(ddmmyy[2:4]), int(ddmmyy[:2]))


@dataclass
class Gga:
    """One GGA sentence, decoded."""

    line: int
    lat_deg: float
    lon_deg: float
    quality: int
    num_sats: float
    hdop: float
    alt_msl_m: float
    geoid_sep_m: float


@dataclass
class Epoch:
    """One receiver output cycle: everything reported for one time of day.

    Attributes:
        tod_text: the time-of-day field that opened the epoch (``021417.00``).
        tod_s: seconds since midnight, UTC.
        line: line number of the first sentence of the epoch.
        date: (year, month, day) from RMC or ZDA in this epoch, else None.
        gga: talker (``GN``, ``GP`` ...) -> its GGA.
        speed_mps, course_deg: ground speed and course from RMC (preferred) or VTG.
        used: (system, satellite) pairs used in the fix (GSA).
        in_view: (talker, satellite) pairs in view (GSV).
        nav_mode: GSA mode (1 no fix, 2 2-D, 3 3-D), 0 if no GSA.
        pdop, hdop, vdop: dilutions of precision from GSA.
        sigma_m: GST 1-sigma (lat, lon, alt) errors, m.
    """

    tod_text: str
    tod_s: float
    line: int
    date: tuple[int, int, int] | None = None
    gga: dict[str, Gga] = field(default_factory=dict)
    speed_mps: float = math.nan
    course_deg: float = math.nan
    rmc_speed: bool = False
    used: set[tuple[str, str]] = field(default_factory=set)
    in_view: set[tuple[str, str]] = field(default_factory=set)
    nav_mode: int = 0
    pdop: float = math.nan
    hdop: float = math.nan
    vdop: float = math.nan
    sigma_m: tuple[float, float, float] | None = None


_TIMED = {"GGA": 1, "RMC": 1, "GLL": 5, "GST": 1, "ZDA": 1}


class EpochBuilder:
    """Feeds decoded sentences into epochs; ``add`` returns an epoch when one is complete."""

    def __init__(self) -> None:
        self.current: Epoch | None = None
        self.orphans = 0  # untimed sentences before the first timed one
        self.repeated = 0  # a second GGA of one talker in one epoch (replaces the first)
        self.sentences: dict[str, int] = {}

    def add(self, fields: list[str], line: int) -> Epoch | None:
        """Add one checked sentence (its comma-separated fields, address first)."""
        address = fields[0]
        kind = address[2:] if len(address) == 5 else address
        self.sentences[kind] = self.sentences.get(kind, 0) + 1
        done: Epoch | None = None
        index = _TIMED.get(kind)
        if index is not None and len(fields) > index and fields[index]:
            tod = fields[index]
            if self.current is None or tod != self.current.tod_text:
                done = self.current
                self.current = Epoch(tod, time_of_day_s(tod), line)
        if self.current is None:
            self.orphans += 1
            return done
        if kind == "GGA" and address[:2] in self.current.gga:
            self.repeated += 1
        _decode(self.current, kind, address[:2], fields, line)
        return done

    def finish(self) -> Epoch | None:
        done, self.current = self.current, None
        return done


def _decode(ep: Epoch, kind: str, talker: str, f: list[str], line: int) -> None:
    if kind == "GGA" and len(f) >= 12:
        ep.gga[talker] = Gga(
            line,
            degrees(f[2], f[3]),
            degrees(f[4], f[5]),
            int(f[6]) if f[6].isdigit() else 0,
            num(f[7]),
            num(f[8]),
            num(f[9]),
            num(f[11]),
        )
    elif kind == "RMC" and len(f) >= 10:
        ep.date = date_ymd(f[9]) or ep.date
        if f[2] == "A":
            ep.speed_mps, ep.course_deg, ep.rmc_speed = num(f[7]) * KNOT_MPS, num(f[8]), True
    elif kind == "VTG" and len(f) >= 8 and not ep.rmc_speed:
        ep.course_deg, ep.speed_mps = num(f[1]), num(f[7]) / 3.6
    elif kind == "GSA" and len(f) >= 18:
        ep.nav_mode = int(f[2]) if f[2].isdigit() else 0
        system = f[18] if len(f) > 18 and f[18] else talker
        ep.used.update((system, s) for s in f[3:15] if s.strip("0"))  # "" or 0: no satellite
        ep.pdop, ep.hdop, ep.vdop = num(f[15]), num(f[16]), num(f[17])
    elif kind == "GSV" and len(f) >= 4:
        ep.in_view.update((talker, f[i]) for i in range(4, len(f) - 3, 4) if f[i].strip("0"))
    elif kind == "GST" and len(f) >= 9:
        ep.sigma_m = (num(f[6]), num(f[7]), num(f[8]))
    elif kind == "ZDA" and len(f) >= 5 and f[2:5] != ["", "", ""]:
        ep.date = (int(num(f[4])), int(num(f[3])), int(num(f[2])))
