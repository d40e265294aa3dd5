"""GPS time: int64 nanoseconds since the GPS epoch, weeks, and the GPS-UTC leap seconds.

``t_ns`` on the GPS time base counts SI nanoseconds since 1980-01-06T00:00:00 (GPS), with no
leap seconds. UTC differs from it by the leap seconds inserted since then (18 s since
2017-01-01). Calendar conversions here treat a calendar date as a label on the GPS scale
(``gps_from_calendar``) or on the UTC scale (``utc_unix_ns_from_gps``), never mixing the two.
"""

from __future__ import annotations

import numpy as np
import numpy.typing as npt

from navreplay.ingest.arrays import I64

NS_PER_S = 1_000_000_000
SECONDS_PER_WEEK = 604_800
NS_PER_WEEK = SECONDS_PER_WEEK * NS_PER_S
GPS_EPOCH = np.datetime64("1980-01-06T00:00:00", "ns")
# The GPS epoch on the Unix (UTC) scale: 1980-01-06 is 3657 days after 1970-01-01.
GPS_EPOCH_UNIX_NS = 315_964_800 * NS_PER_S

# UTC dates on which GPS - UTC grew by one second (IERS Bulletin C), after the GPS epoch.
LEAP_DATES_UTC = (
    "1981-07-01",
    "1982-07-01",
    "1983-07-01",
    "1985-07-01",
    "1988-01-01",
    "1990-01-01",
    "1991-01-01",
    "1992-07-01",
    "1993-07-01",
    "1994-07-01",
    "1996-01-01",
    "1997-07-01",
    "1999-01-01",
    "2006-01-01",
    "2009-01-01",
    "2012-07-01",
    "2015-07-01",
    "2017-01-01",
)
# POSIX (UTC) ns of each of those midnights, and the GPS time (ns) at which each takes effect:
# UTC midnight plus the new offset.
LEAP_STEPS_UNIX_NS = np.array(
    [np.datetime64(d, "ns").astype(np.int64) for d in LEAP_DATES_UTC], dtype=np.int64
)
_LEAP_GPS_NS = np.array(
    [
        (np.datetime64(d, "ns") - GPS_EPOCH).astype(np.int64) + (i + 1) * NS_PER_S
        for i, d in enumerate(LEAP_DATES_UTC)
    ],
    dtype=np.int64,
)


def gps_from_calendar(stamp: str) -> int:
    """GPS ``t_ns`` of an ISO calendar stamp read on the GPS scale (``2026-11-18T02:30:00``)."""
    return int((np.datetime64(stamp, "ns") - GPS_EPOCH).astype(np.int64))


def calendar_from_gps(t_ns: int) -> np.datetime64:
    """The calendar label (GPS scale) of a GPS ``t_ns``, as ``datetime64[ns]``."""
    return GPS_EPOCH + np.timedelta64(int(t_ns), "ns")


def leap_seconds(t_ns: int | I64) -> npt.NDArray[np.int64]:
    """GPS - UTC in whole seconds at GPS time ``t_ns`` (0 before mid-1981, 18 since 2017)."""
    return np.searchsorted(_LEAP_GPS_NS, np.asarray(t_ns, dtype=np.int64), side="right").astype(
        np.int64
    )


def utc_unix_ns_from_gps(t_ns: int | I64) -> npt.NDArray[np.int64]:
    """UTC as ns since the Unix epoch (what ROS stamps carry) of GPS ``t_ns``."""
    t = np.asarray(t_ns, dtype=np.int64)
    return t + GPS_EPOCH_UNIX_NS - leap_seconds(t) * NS_PER_S


def week_and_seconds(t_ns: int) -> tuple[int, float]:
    """(GPS week, seconds of week) of a GPS ``t_ns``; the week is the continuous count."""
    week, rem = divmod(int(t_ns), NS_PER_WEEK)
    return week, rem / NS_PER_S
