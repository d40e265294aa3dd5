"""Vehicle clocks of autopilot logs: boot segments, pairings with GPS/UTC time, week rollover.

Autopilots stamp their messages with time since boot (MAVLink ``time_boot_ms`` or
``time_usec``, DataFlash ``TimeUS``, ULog ``timestamp``). To put a log on GPS time the reader
pairs that clock with a message carrying both clocks (MAVLink ``SYSTEM_TIME``, DataFlash
``GPS`` GWk/GMS, ULog ``time_utc_usec``): the offset is the median over all pairs of one boot,
so single late or jittery messages do not move it.

- ``BootTracker`` splits a log into boot segments where the vehicle clock drops (a reboot
  mid-log resets ``time_boot_ms`` to 0: catalogue case 37). Segments start at byte offsets.
  A drop must exceed ``RESET_DROP_NS`` (late telemetry packets are not reboots), so a reboot
  after a session shorter than that goes unnoticed (both sessions share one pairing; the
  stream hygiene still reports the clock step).
- ``OffsetAccumulator`` keeps, per segment, the median of each block's offsets and the count,
  and returns their weighted median: bounded memory for logs of any length.
- ``unroll_gps_week`` undoes a GPS week-number rollover (1024 weeks, catalogue case 35) by
  moving the log forward by whole rollovers as long as it stays before a reference time it
  cannot postdate (the file's modification time or the dataset's date; the tlog reader snaps
  UTC values to its stamps, ``ROLLOVER_NS``). Nearest-epoch snapping would move a 2015 log
  copied in 2026 (11 years: more than half a rollover) to 2034.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from navreplay.ingest.arrays import I64
from navreplay.ingest.damage import DamageLog
from navreplay.ingest.timebase import NS_PER_S, SECONDS_PER_WEEK

#: A drop of the vehicle clock by more than this starts a new boot segment. Telemetry links
#: deliver packets late by a second or more (a radio's buffer); a reboot restarts near zero.
RESET_DROP_NS = 10 * NS_PER_S
ROLLOVER_WEEKS = 1024
ROLLOVER_NS = ROLLOVER_WEEKS * SECONDS_PER_WEEK * NS_PER_S


@dataclass
class BootTracker:
    """Boot segments of one vehicle clock, fed in file order.

    Attributes:
        starts: byte offset where each segment starts (the first is 0).
        resets: (offset, clock before, clock after) of each detected reset, ns.
    """

    starts: list[int] = field(default_factory=lambda: [0])
    resets: list[tuple[int, int, int]] = field(default_factory=list)
    _max: int | None = None

    def note_resets(self, damage: DamageLog, *, reboot: str, clock: str) -> None:
        """Count each reset in ``damage`` and describe it: ``reboot`` names the event and
        ``clock`` the vehicle clock in the log's terms."""
        for offset, before, after in self.resets:
            damage.count("boot_resets")
            damage.note(
                f"{reboot} at offset {offset}: {clock} dropped from {before / 1e9:.3f} s to "
                f"{after / 1e9:.3f} s; segments paired separately"
            )

    def push(self, offsets: I64, boot_ns: I64) -> None:
        """Take the clock readings of one block (file order)."""
        lo = 0
        n = len(boot_ns)
        while lo < n:
            part = boot_ns[lo:]
            running = np.maximum.accumulate(part)
            if self._max is not None:
                running = np.maximum(running, self._max)
            drops = np.flatnonzero(part < running - RESET_DROP_NS)
            if not drops.size:
                self._max = int(running[-1])
                return
            i = lo + int(drops[0])
            before = int(running[drops[0]])
            self.starts.append(int(offsets[i]))
            self.resets.append((int(offsets[i]), before, int(boot_ns[i])))
            self._max = None
            lo = i

    def segment_of(self, offsets: I64) -> I64:
        """Segment index of each byte offset."""
        idx = np.searchsorted(np.asarray(self.starts, np.int64), offsets, side="right") - 1
        return np.asarray(idx, dtype=np.int64)


@dataclass
class OffsetAccumulator:
    """Median offset per segment from per-block medians (see the module docstring)."""

    _parts: dict[int, list[tuple[int, int]]] = field(default_factory=dict)

    def add(self, segments: I64, offsets_ns: I64) -> None:
        if not len(offsets_ns):
            return
        for seg in np.unique(segments).tolist():
            sel = offsets_ns[segments == seg]
            med = int(np.sort(sel)[len(sel) // 2])
            self._parts.setdefault(int(seg), []).append((med, len(sel)))

    def median(self, segment: int) -> int | None:
        parts = self._parts.get(segment)
        if not parts:
            return None
        parts = sorted(parts)
        counts = np.cumsum([c for _, c in parts])
        k = int(np.searchsorted(counts, counts[-1] / 2.0))
        return parts[k][0]

    def count(self, segment: int) -> int:
        return sum(c for _, c in self._parts.get(segment, ()))


#: The reference date may precede the log by this much (a dataset's ``utc_date`` is the day).
ROLLOVER_SLACK_NS = 2 * 86_400 * NS_PER_S


def unroll_gps_week(week: I64, tow_ns: I64, reference_gps_ns: int) -> tuple[I64, int]:
    """GPS weeks corrected by the most multiples of 1024 that keep the log before
    ``reference_gps_ns`` (plus ``ROLLOVER_SLACK_NS``).

    Returns the corrected weeks and the number of weeks added (0 when none).
    """
    if not len(week):
        return week, 0
    t = week[0] * SECONDS_PER_WEEK * NS_PER_S + tow_ns[0]
    k = (reference_gps_ns + ROLLOVER_SLACK_NS - int(t)) // ROLLOVER_NS
    if k <= 0:
        return week, 0
    return week + k * ROLLOVER_WEEKS, k * ROLLOVER_WEEKS


def note_week_rollover(damage: DamageLog, rows: int, what: str, weeks: int, how: str) -> None:
    """Count and describe ``rows`` ``what`` moved forward by ``weeks`` GPS weeks (``how``)."""
    damage.count("gps_week_rollover_corrected", rows)
    damage.note(f"GPS week rollover: {rows} {what} corrected by +{weeks} weeks{how}")
