"""The survey pass over a tlog: what it holds, and how its clocks map onto UTC/GPS time.

A tlog carries three clocks: the ground station's wall clock in every record's stamp (UTC,
receive time), the vehicle's boot clock (``time_boot_ms``, boot-time ``time_usec``) and, once
the vehicle has a GPS fix, the vehicle's UTC (``SYSTEM_TIME.time_unix_usec``, epoch-valued
``time_usec``). The survey (one scan, before reading) finds:

- the vehicle: the sender ``(sysid, compid)`` with the most ``time_boot_ms`` packets; packets
  of other senders (the GCS, a gimbal with its own clock) are not read into tables;
- its boot segments (``BootTracker``): a reboot mid-log (case 37) starts a new segment, and
  each segment is paired separately;
- per segment, the pairing ``boot -> UTC``: the median of ``time_unix_usec - time_boot_ms``
  over SYSTEM_TIME packets (the vehicle's GPS-derived UTC), else the median of
  ``stamp - time_boot_ms`` (the GCS clock: receive latency included);
- per segment, ``stamp -> UTC`` for messages without a time field (SIMSTATE): the median of
  ``epoch time_usec - stamp`` over epoch-stamped IMU packets, else the boot pairing minus
  ``stamp - boot``;
- GPS week rollover (case 35): vehicle UTC values 1024 weeks away from the tlog stamps are
  corrected (the stamps are the reference) and counted;
- message counts per stream and instance, first/last stamps, and the geoid undulation
  (median ``alt_ellipsoid - alt`` of GPS packets);
- the HEARTBEAT ``(type, autopilot)`` counts per sender, the vehicle kind (``ingest.platform``).

The dataset base is GPS (UTC converted with the leap-second table) when every segment is
paired with the vehicle's GPS-derived UTC, else UTC (the GCS clock).
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import numpy.typing as npt

from navreplay.ingest.arrays import I64
from navreplay.ingest.platform import UNKNOWN, Platform, from_heartbeats, with_q_enable
from navreplay.ingest.readers.mavlink._mavscan import VALID, gather
from navreplay.ingest.readers.mavlink.mavclock import ROLLOVER_NS, BootTracker, OffsetAccumulator
from navreplay.ingest.readers.mavlink.mavdialect import Dialect, MessageDef
from navreplay.ingest.readers.mavlink.mavmsgs import BY_MESSAGE, MavStream
from navreplay.ingest.readers.mavlink.tlogscan import Packets, ScanStats, scan_blocks
from navreplay.ingest.timebase import TimeBase

#: ``time_usec`` values at or above this (2001-09-09) are UNIX epoch, below it time since boot
#: (the MAVLink convention: "the receiving end can infer the format from the magnitude").
EPOCH_MIN_US = 10**15
_EPOCH_NOW = ("RAW_IMU", "HIGHRES_IMU")
_GPS = ("GPS_RAW_INT", "GPS2_RAW")


def field_values(p: Packets, idx: npt.NDArray[np.intp], mdef: MessageDef, name: str) -> np.ndarray:
    """One field of the packets ``idx`` (all of message ``mdef``), zero-trimming undone."""
    return decode(p, idx, mdef)[name]


def decode(p: Packets, idx: npt.NDArray[np.intp], mdef: MessageDef) -> np.ndarray:
    """The payloads of packets ``idx`` as a structured array in ``mdef``'s wire layout."""
    out = np.empty((len(idx), mdef.length), np.uint8)
    gather(p.buf, p.payload[idx], p.payload_len[idx], out)
    return out.view(mdef.dtype)[:, 0]


@dataclass
class SegmentClock:
    """How one boot segment's clocks map to UTC (ns offsets), and where they come from."""

    boot_to_utc_ns: int | None
    boot_source: str
    stamp_to_utc_ns: int
    vehicle_utc: bool


@dataclass
class TlogSurvey:
    """Everything the survey pass learns (see the module docstring)."""

    stats: ScanStats = field(default_factory=ScanStats)
    vehicle: int | None = None
    trackers: dict[int, BootTracker] = field(default_factory=dict)
    boot_packets: Counter[int] = field(default_factory=Counter)
    counts: Counter[tuple[int, str, int]] = field(default_factory=Counter)
    first_stamp_us: dict[tuple[int, str, int], int] = field(default_factory=dict)
    last_stamp_us: dict[tuple[int, str, int], int] = field(default_factory=dict)
    segments: list[SegmentClock] = field(default_factory=list)
    rollover_weeks: int = 0
    rollover_rows: int = 0
    undulation_m: float | None = None
    base: TimeBase = TimeBase.UTC
    heartbeats: dict[int, Counter[tuple[int, int]]] = field(default_factory=dict)
    q_enable: dict[int, float] = field(default_factory=dict)
    _stamp_minus_boot: dict[int, OffsetAccumulator] = field(default_factory=dict)
    _systime: dict[int, OffsetAccumulator] = field(default_factory=dict)
    _epoch_minus_stamp: dict[int, OffsetAccumulator] = field(default_factory=dict)
    _undulation: OffsetAccumulator = field(default_factory=OffsetAccumulator)

    def platform(self) -> Platform:
        """The vehicle kind from the HEARTBEAT ``type`` of the vehicle, else of any other
        sender that is a flight controller (GCS heartbeats never count); a fixed wing whose
        ``Q_ENABLE`` parameter (PARAM_VALUE) is set is a QuadPlane, a VTOL."""
        order = sorted(self.heartbeats, key=lambda k: (k != self.vehicle, k))
        for sender in order:
            beats = self.heartbeats[sender]
            found = from_heartbeats((t, a, n) for (t, a), n in beats.items())
            if found.known:
                return with_q_enable(found, self.q_enable.get(sender))
        return UNKNOWN

    @property
    def tracker(self) -> BootTracker:
        return self.trackers.get(self.vehicle or -1) or BootTracker()

    def decisions(self) -> list[str]:
        out = []
        for i, seg in enumerate(self.segments):
            start = self.tracker.starts[i]
            out.append(
                f"boot segment {i} (from offset {start}): vehicle clock -> UTC by "
                f"{seg.boot_source}; records without a time field use the tlog stamp "
                f"{seg.stamp_to_utc_ns / 1e9:+.3f} s"
            )
        return out


def survey(path: Path, dialect: Dialect) -> TlogSurvey:
    """One scan of ``path`` (see the module docstring)."""
    s = TlogSurvey()
    boot_ids = boot_messages(dialect)
    systime = dialect.by_name("SYSTEM_TIME")
    heartbeat = dialect.by_name("HEARTBEAT")
    param = dialect.by_name("PARAM_VALUE")
    for p in scan_blocks(path, dialect, s.stats):
        ok = p.flag == VALID
        _boot_clock(s, p, ok, boot_ids)
        src = p.source
        for sender in np.unique(src[ok]).tolist():
            mine = ok & (src == sender)
            s.trackers.setdefault(sender, BootTracker())
            if systime is not None:
                _systime_pairs(s, p, mine, systime, sender)
            if heartbeat is not None:
                _heartbeats(s, p, mine, heartbeat, sender)
            if param is not None:
                _q_enable(s, p, mine, param, sender)
            _streams(s, p, mine, dialect, sender)
    _finish(s)
    return s


def boot_messages(dialect: Dialect) -> dict[int, MessageDef]:
    """Messages whose ``time_boot_ms`` is the sender's clock at sending (commands excluded)."""
    return {
        msgid: dialect.message(msgid)
        for name, msgid in dialect.ids.items()
        if not name.startswith("SET_") and "time_boot_ms" in dialect.message(msgid).offsets
    }


def _boot_clock(
    s: TlogSurvey, p: Packets, ok: npt.NDArray[np.bool_], ids: dict[int, MessageDef]
) -> None:
    offsets, boot, stamp, src = [], [], [], []
    present = np.unique(p.msgid[ok]).tolist()
    for msgid in present:
        mdef = ids.get(msgid)
        if mdef is None:
            continue
        idx = np.flatnonzero(ok & (p.msgid == msgid))
        boot.append(field_values(p, idx, mdef, "time_boot_ms").astype(np.int64) * 1_000_000)
        offsets.append(p.offset[idx])
        stamp.append(p.stamp_us[idx] * 1000)
        src.append(p.source[idx])
    if not offsets:
        return
    order = np.argsort(np.concatenate(offsets), kind="stable")
    off, b, st, sr = (np.concatenate(a)[order] for a in (offsets, boot, stamp, src))
    for sender in np.unique(sr).tolist():
        m = sr == sender
        tracker = s.trackers.setdefault(sender, BootTracker())
        tracker.push(off[m], b[m])
        s.boot_packets[sender] += int(m.sum())
        acc = s._stamp_minus_boot.setdefault(sender, OffsetAccumulator())
        acc.add(tracker.segment_of(off[m]), st[m] - b[m])


def _rollover(s: TlogSurvey, utc_ns: I64, stamp_ns: I64) -> I64:
    """Undo a 1024-week rollover of vehicle UTC values against the tlog stamps."""
    k = np.rint((stamp_ns - utc_ns) / ROLLOVER_NS).astype(np.int64)
    fixed = k != 0
    if fixed.any():
        s.rollover_weeks = max(s.rollover_weeks, int(k[fixed].max()) * 1024)
        s.rollover_rows += int(fixed.sum())
    return utc_ns + k * ROLLOVER_NS


def _systime_pairs(
    s: TlogSurvey, p: Packets, mine: npt.NDArray[np.bool_], mdef: MessageDef, sender: int
) -> None:
    idx = np.flatnonzero(mine & (p.msgid == mdef.msgid))
    if not len(idx):
        return
    rec = decode(p, idx, mdef)
    unix_ns = rec["time_unix_usec"].astype(np.int64) * 1000
    valid = unix_ns > 0
    if not valid.any():
        return
    idx, rec, unix_ns = idx[valid], rec[valid], unix_ns[valid]
    unix_ns = _rollover(s, unix_ns, p.stamp_us[idx] * 1000)
    boot_ns = rec["time_boot_ms"].astype(np.int64) * 1_000_000
    segs = s.trackers[sender].segment_of(p.offset[idx])
    s._systime.setdefault(sender, OffsetAccumulator()).add(segs, unix_ns - boot_ns)


def _heartbeats(
    s: TlogSurvey, p: Packets, mine: npt.NDArray[np.bool_], mdef: MessageDef, sender: int
) -> None:
    idx = np.flatnonzero(mine & (p.msgid == mdef.msgid))
    if not len(idx):
        return
    rec = decode(p, idx, mdef)
    pairs = np.column_stack([rec["type"].astype(np.int64), rec["autopilot"].astype(np.int64)])
    values, counts = np.unique(pairs, axis=0, return_counts=True)
    beats = s.heartbeats.setdefault(sender, Counter())
    for (t, a), n in zip(values.tolist(), counts.tolist(), strict=True):
        beats[(t, a)] += n


def _q_enable(
    s: TlogSurvey, p: Packets, mine: npt.NDArray[np.bool_], mdef: MessageDef, sender: int
) -> None:
    idx = np.flatnonzero(mine & (p.msgid == mdef.msgid))
    if not len(idx):
        return
    rec = decode(p, idx, mdef)
    hit = np.flatnonzero(rec["param_id"] == b"Q_ENABLE")
    if len(hit):
        s.q_enable[sender] = float(rec["param_value"][hit[-1]])


def _streams(
    s: TlogSurvey,
    p: Packets,
    mine: npt.NDArray[np.bool_],
    dialect: Dialect,
    sender: int,
) -> None:
    for msgid in np.unique(p.msgid[mine]).tolist():
        name = dialect.msg_name(msgid)
        specs = BY_MESSAGE.get(name)
        if specs is None:
            continue
        idx = np.flatnonzero(mine & (p.msgid == msgid))
        mdef = dialect.message(msgid)
        rec = decode(p, idx, mdef)
        for spec in specs:
            carried = spec.present(rec)
            inst = instances(spec, rec)
            for i in np.unique(inst[carried]).tolist():
                sel = idx[(inst == i) & carried]
                key = (sender, spec.name, int(i))
                s.counts[key] += len(sel)
                s.first_stamp_us.setdefault(key, int(p.stamp_us[sel[0]]))
                s.last_stamp_us[key] = int(p.stamp_us[sel[-1]])
        if name in _EPOCH_NOW:
            usec = rec["time_usec"].astype(np.int64)
            epoch = usec >= EPOCH_MIN_US
            if epoch.any():
                stamp = p.stamp_us[idx[epoch]] * 1000
                utc = _rollover(s, usec[epoch] * 1000, stamp)
                segs = s.trackers[sender].segment_of(p.offset[idx[epoch]])
                s._epoch_minus_stamp.setdefault(sender, OffsetAccumulator()).add(segs, utc - stamp)
        if name in _GPS and "alt_ellipsoid" in (rec.dtype.names or ()):
            ell = rec["alt_ellipsoid"].astype(np.int64)
            have = ell != 0
            if have.any():
                n_mm = ell[have] - rec["alt"][have].astype(np.int64)
                s._undulation.add(np.zeros(int(have.sum()), np.int64), n_mm)


def instances(spec: MavStream, rec: np.ndarray) -> I64:
    """The sensor instance of each decoded message of ``spec``."""
    if spec.instance_field is None:
        return np.full(len(rec), spec.instance, dtype=np.int64)
    return np.asarray(rec[spec.instance_field], dtype=np.int64)


def _finish(s: TlogSurvey) -> None:
    if s.boot_packets:
        s.vehicle = max(s.boot_packets, key=lambda k: (s.boot_packets[k], -k))
    elif s.trackers:
        senders = [k for k in s.trackers if k // 256 != 255] or list(s.trackers)
        s.vehicle = senders[0]
    v = s.vehicle if s.vehicle is not None else -1
    und = s._undulation.median(0)
    s.undulation_m = None if und is None else und * 1e-3
    stamp_boot = s._stamp_minus_boot.get(v, OffsetAccumulator())
    systime = s._systime.get(v, OffsetAccumulator())
    epoch = s._epoch_minus_stamp.get(v, OffsetAccumulator())
    all_vehicle = True
    for seg in range(len(s.tracker.starts)):
        sb, st, ep = stamp_boot.median(seg), systime.median(seg), epoch.median(seg)
        if st is not None:
            boot, source = st, f"SYSTEM_TIME (vehicle UTC, {systime.count(seg)} pairs)"
        elif sb is not None:
            boot, source = sb, "the tlog stamps (GCS wall clock, receive latency included)"
        else:
            boot, source = None, "nothing (no time_boot_ms packets)"
        if ep is not None:
            stamp = ep
        elif st is not None and sb is not None:
            stamp = st - sb
        else:
            stamp = 0
        vehicle_utc = st is not None or ep is not None
        all_vehicle &= vehicle_utc
        s.segments.append(SegmentClock(boot, source, stamp, vehicle_utc))
    s.base = TimeBase.GPS if all_vehicle and s.segments else TimeBase.UTC


class HeldClock:
    """Vehicle time for packets without a time field, from the packets around them.

    A message without a time field (SIMSTATE) is sent in the same burst as the timed message
    before it (ArduPilot sends it right after ATTITUDE): it gets that packet's vehicle time,
    advanced by the difference of their tlog stamps (zero within a burst). Before any timed
    packet, the segment's stamp mapping applies.

    Args:
        stamp_to_utc_ns: the fallback mapping of tlog stamps onto the vehicle clock.
    """

    def __init__(self, stamp_to_utc_ns: int) -> None:
        self.fallback = stamp_to_utc_ns
        self._off = np.empty(0, np.int64)
        self._utc = np.empty(0, np.int64)
        self._stamp = np.empty(0, np.int64)

    def push(self, offsets: I64, utc_ns: I64, stamp_ns: I64) -> None:
        """Timed packets of the next block (file order); the last of the previous is kept."""
        keep = slice(len(self._off) - 1, None) if len(self._off) else slice(0, 0)
        self._off = np.concatenate([self._off[keep], offsets])
        self._utc = np.concatenate([self._utc[keep], utc_ns])
        self._stamp = np.concatenate([self._stamp[keep], stamp_ns])

    def at(self, offsets: I64, stamp_ns: I64) -> I64:
        """Vehicle UTC for untimed packets at ``offsets`` with tlog stamps ``stamp_ns``."""
        j = np.searchsorted(self._off, offsets) - 1
        have = j >= 0
        jj = np.maximum(j, 0)
        if not len(self._off):
            return stamp_ns + self.fallback
        held = self._utc[jj] + (stamp_ns - self._stamp[jj])
        return np.where(have, held, stamp_ns + self.fallback)
