"""Time bases of canonical ``t_ns`` and the conversions between them.

Every canonical table counts ``t_ns`` (int64 nanoseconds) on one declared base:

- ``gps``: GPS time, nanoseconds since the GPS epoch 1980-01-06T00:00:00 (continuous, no leap
  seconds); ``week * 604800 s + time of week``. RINEX epochs, GNSS receivers, ArduPilot GPS
  week/ms and Android ``TimeNanos - FullBiasNanos`` all live here.
- ``utc``: POSIX time, nanoseconds since 1970-01-01T00:00:00 UTC (leap seconds not counted).
  ROS header stamps and MAVLink tlog wall-clock stamps are on this base.
- ``recorder``: the logger's own clock (boot time, simulated time); its epoch is unknown, so it
  converts to nothing without a clock pairing supplied by the reader.

A dataset merged from several files is put on one base (``reconcile``): GPS when any stream is
on GPS time (UTC streams convert exactly with the leap-second table), else UTC, else recorder.
The leap-second count used is written to the report. GPS-side conversions are those of
``ingest.gpstime`` (which the log writers use); this module adds the UTC-side view of the same
IERS leap-second list, so a POSIX stamp converts to GPS time without iterating.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass
from enum import StrEnum

import numpy as np
import numpy.typing as npt

from navreplay.ingest.arrays import I64
from navreplay.ingest.errors import IngestError
from navreplay.ingest.gpstime import (
    GPS_EPOCH_UNIX_NS,
    LEAP_STEPS_UNIX_NS,
    NS_PER_S,
    SECONDS_PER_WEEK,
    utc_unix_ns_from_gps,
)

__all__ = ["GPS_EPOCH_UNIX_NS", "NS_PER_S", "SECONDS_PER_WEEK"]

# The leap-second table lives in ingest.gpstime (one source of truth).
_LEAP_STEPS_UNIX_NS = LEAP_STEPS_UNIX_NS

# Stamps before this (2000-01-01) cannot be wall-clock UTC from a modern recorder: a ROS bag
# with such header stamps ran on simulated or boot time.
MIN_PLAUSIBLE_UTC_NS = 946_684_800 * NS_PER_S


class TimeBase(StrEnum):
    """What a ``t_ns`` value counts (see the module docstring)."""

    GPS = "gps"
    UTC = "utc"
    RECORDER = "recorder"


def leap_seconds_at_utc(utc_ns: int | I64) -> I64:
    """GPS - UTC in whole seconds at POSIX time ``utc_ns`` (0 before 1981-07-01)."""
    return np.searchsorted(_LEAP_STEPS_UNIX_NS, np.asarray(utc_ns, dtype=np.int64), side="right")


def utc_to_gps_ns(utc_ns: I64) -> I64:
    """POSIX UTC nanoseconds -> GPS nanoseconds since the GPS epoch."""
    utc = np.asarray(utc_ns, dtype=np.int64)
    return utc - GPS_EPOCH_UNIX_NS + leap_seconds_at_utc(utc).astype(np.int64) * NS_PER_S


def gps_to_utc_ns(gps_ns: I64) -> I64:
    """GPS nanoseconds since the GPS epoch -> POSIX UTC nanoseconds (``ingest.gpstime``).

    The inverse of ``utc_to_gps_ns`` except inside an inserted leap second, which POSIX time
    cannot represent.
    """
    return utc_unix_ns_from_gps(np.asarray(gps_ns, dtype=np.int64))


def gps_week_tow_to_ns(week: npt.ArrayLike, tow_ns: npt.ArrayLike) -> I64:
    """GPS week (full, not modulo 1024) and time of week in ns -> GPS nanoseconds."""
    w = np.asarray(week, dtype=np.int64)
    return w * (SECONDS_PER_WEEK * NS_PER_S) + np.asarray(tow_ns, dtype=np.int64)


@dataclass(frozen=True)
class Reconciliation:
    """How each stream's base maps onto the dataset's base.

    Attributes:
        base: the dataset's time base.
        leap_seconds: GPS - UTC applied to UTC streams (None when no conversion happened).
        decisions: one human-readable line per decision, for the report.
    """

    base: TimeBase
    leap_seconds: int | None
    decisions: tuple[str, ...]


def reconcile(
    stream_bases: Iterable[tuple[str, TimeBase]],
    *,
    requested: str = "auto",
    sample_utc_ns: int | None = None,
) -> Reconciliation:
    """Choose the dataset's time base for streams on ``stream_bases`` ((stream, base) pairs).

    Args:
        stream_bases: the streams that will be written and the base each is stamped on.
        requested: ``auto`` or a ``TimeBase`` value from the dataset descriptor.
        sample_utc_ns: a UTC instant inside the data, for the leap-second count reported.

    Raises:
        IngestError: a recorder-clock stream must be merged with a wall-clock one (no pairing),
            or the requested base cannot be reached from the streams' bases.
    """
    pairs = list(stream_bases)
    bases = {b for _, b in pairs}
    if requested == "auto":
        if TimeBase.GPS in bases:
            target = TimeBase.GPS
        elif TimeBase.UTC in bases:
            target = TimeBase.UTC
        else:
            target = TimeBase.RECORDER
    else:
        target = TimeBase(requested)
    decisions: list[str] = []
    leap: int | None = None
    for name, base in pairs:
        if base == target:
            decisions.append(f"{name}: {base.value} (as recorded)")
        elif {base, target} == {TimeBase.UTC, TimeBase.GPS}:
            if sample_utc_ns is not None:
                leap = int(leap_seconds_at_utc(sample_utc_ns))
            decisions.append(
                f"{name}: {base.value} -> {target.value} with the leap-second table"
                + (f" (GPS - UTC = {leap} s at the data)" if leap is not None else "")
            )
        else:
            raise IngestError(
                f"stream {name} is stamped on the {base.value} clock and cannot be converted to "
                f"{target.value} time: no pairing between the two clocks is known",
                hint="ingest the files separately, or set time_base in dataset.yaml to "
                f"{base.value}",
            )
    return Reconciliation(target, leap, tuple(decisions))


def convert(t_ns: I64, source: TimeBase, target: TimeBase) -> I64:
    """Convert ``t_ns`` from ``source`` to ``target`` base (UTC <-> GPS, or identity)."""
    if source == target:
        return t_ns
    if source == TimeBase.UTC and target == TimeBase.GPS:
        return utc_to_gps_ns(t_ns)
    if source == TimeBase.GPS and target == TimeBase.UTC:
        return gps_to_utc_ns(t_ns)
    raise IngestError(f"no conversion from {source.value} to {target.value} time")
