"""MAVLink telemetry logs (``.tlog``): ``[u64 big-endian UNIX us][MAVLink v1/v2 packet]``.

Decoding uses pymavlink's dialect definitions (``ardupilotmega`` by default, ``mavlink.dialect``
in dataset.yaml) for the CRC seeds, field layout and scalings, but never pymavlink's
per-packet parser: each block of the file is framed and CRC-checked by a compiled scan
(``ingest.readers.mavlink._mavscan``), packets are grouped by message, and payloads are decoded with
one structured-dtype view per message and block (``ingest.readers.mavlink.mavmsgs`` converts them).

Streams (``--list`` keys): the message name, with ``[n]`` for sensor instance n > 0
(``RAW_IMU[1]``); ``StreamInfo.instance`` is the IMU/receiver number, which ``imu.instance``
and ``gnss.instance`` select. Only the vehicle's packets are read
(``ingest.readers.mavlink.tlogclock`` explains the vehicle, its boot segments and the time base).

Damage (catalogue cases 13-15, 35, 37), recorded after the read pass:

- garbage bytes between packets are skipped (resynchronised on the next packet whose CRC
  checks); never decoded, so no bogus ``BAD_DATA`` timestamps reach a table; runs and bytes
  counted with offsets;
- packets failing their CRC are skipped and counted per message; packets lost in transit are
  counted from sequence-number gaps per sender;
- a message whose packets nearly all fail their CRC, or many packets with ids the dialect
  lacks, suggest a wrong dialect: recorded as a defect (E-FATAL under ``--strict``);
- a trailing partial record is dropped and reported with its offset;
- boot resets and GPS week rollover corrections are noted and counted.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence

import numpy as np
import numpy.typing as npt

from navreplay.ingest.arrays import I64
from navreplay.ingest.context import (
    LogContext,
    changes,
    decode_text,
    forward,
    mavlink_mode_name,
)
from navreplay.ingest.damage import Completeness, Defect
from navreplay.ingest.detect import Detected, Format
from navreplay.ingest.errors import CorruptLogError
from navreplay.ingest.readers.asof import AsofJoin, Left, through
from navreplay.ingest.readers.base import (
    Batch,
    Inventory,
    LogReader,
    ReadContext,
    Selection,
    StreamInfo,
)
from navreplay.ingest.readers.mavlink._mavscan import VALID
from navreplay.ingest.readers.mavlink.mavclock import ROLLOVER_NS, note_week_rollover
from navreplay.ingest.readers.mavlink.mavdialect import load_dialect
from navreplay.ingest.readers.mavlink.mavmsgs import BY_NAME, Extras, MavStream
from navreplay.ingest.readers.mavlink.tlogclock import (
    EPOCH_MIN_US,
    HeldClock,
    TlogSurvey,
    boot_messages,
    decode,
    instances,
    survey,
)
from navreplay.ingest.readers.mavlink.tlogscan import Packets, ScanStats, scan_blocks
from navreplay.ingest.schema import EventKind, TableName
from navreplay.ingest.timebase import TimeBase, utc_to_gps_ns

JOIN_TOLERANCE_NS = 100_000_000
#: A message id is suspected of a dialect mismatch when this share of its packets fail CRC.
DIALECT_CRC_SHARE = 0.9
#: ... or when packets with ids the dialect lacks are this share of all framed packets.
DIALECT_UNKNOWN_SHARE = 0.1


class TlogReader(LogReader):
    """Reader of one MAVLink tlog."""

    format = Format.TLOG

    def __init__(self, detected: Detected, ctx: ReadContext) -> None:
        super().__init__(detected, ctx)
        name = ctx.config.mavlink.dialect if ctx.config is not None else "ardupilotmega"
        self.dialect = load_dialect(name)
        self._survey: TlogSurvey | None = None
        self._boot_ids = boot_messages(self.dialect)
        self._held = HeldClock(0)

    def _surveyed(self) -> TlogSurvey:
        if self._survey is None:
            found = survey(self.file, self.dialect)
            if not found.stats.packets:
                raise CorruptLogError(
                    "no MAVLink packet found: not a tlog, or damaged throughout "
                    f"({found.stats.garbage_bytes} bytes that do not frame)",
                    path=self.file,
                    offset=0,
                    hint="check the file; with --format tlog forced, check the format",
                )
            self._survey = found
        return self._survey

    # ----------------------------------------------------------------------------- inventory
    def inventory(self) -> Inventory:
        s = self._surveyed()
        seg0 = s.segments[0].stamp_to_utc_ns if s.segments else 0
        streams: list[StreamInfo] = []
        for (sender, name, inst), count in sorted(s.counts.items()):
            if sender != s.vehicle:
                continue
            spec = BY_NAME[name]
            key = (sender, name, inst)
            streams.append(
                StreamInfo(
                    key=spec.key(inst),
                    msgtype=spec.message,
                    count=count,
                    start_ns=self._to_base(s.first_stamp_us[key] * 1000 + seg0),
                    end_ns=self._to_base(s.last_stamp_us[key] * 1000 + seg0),
                    table=spec.table,
                    time_base=s.base,
                    frame="frd" if spec.table in (TableName.IMU, TableName.MAG) else "ned",
                    instance=inst,
                    detail=spec.detail,
                )
            )
        listed = {st.msgtype for st in streams}
        joined = {j.message: spec.message for spec in BY_NAME.values() for j in spec.joins}
        for msgid, count in sorted(s.stats.valid.items()):
            name = self.dialect.msg_name(msgid)
            if name not in listed:
                detail = f"joined into {joined[name]}" if name in joined else "not converted"
                detail = _CONTEXT.get(name, detail)
                streams.append(
                    StreamInfo(name, name, count, None, None, None, s.base, detail=detail)
                )
        notes = [f"MAVLink dialect {self.dialect.name}; CRC checked on every packet"]
        notes += s.decisions()
        platform = s.platform()
        notes.append(f"platform: {platform.text()}")
        return Inventory(self.path, self.format, tuple(streams), tuple(notes), platform)

    def _to_base(self, utc_ns: int) -> int:
        if self._surveyed().base == TimeBase.GPS:
            return int(utc_to_gps_ns(np.array([utc_ns], np.int64))[0])
        return utc_ns

    # ---------------------------------------------------------------------------------- read
    def read(self, selections: Sequence[Selection]) -> Iterator[Batch]:
        s = self._surveyed()
        wanted = _wanted(selections)
        extras = Extras(s.undulation_m)
        joins = {  # a chain per stream: its rows pass each join in turn
            key: [AsofJoin(j.columns, JOIN_TOLERANCE_NS) for j in spec.joins]
            for key, (spec, _) in wanted.items()
            if spec.joins
        }
        held = any(
            spec.time_field is None or any(j.time_field is None for j in spec.joins)
            for spec, _ in wanted.values()
        )
        pending: dict[str, Batch] = {}  # counters of joined batches not yet released
        stats = ScanStats()
        self._held = HeldClock(s.segments[0].stamp_to_utc_ns if s.segments else 0)
        for p in scan_blocks(self.file, self.dialect, stats):
            mine = (p.flag == VALID) & (p.source == s.vehicle)
            if held:
                self._update_held(p, mine)
            for key, (spec, inst) in wanted.items():
                batch = self._stream_batch(p, mine, spec, inst, key, extras)
                if batch is None:
                    continue
                chain = joins.get(key)
                if chain is None:
                    yield batch
                    continue
                self._push_joins(p, mine, spec, chain, batch, extras)
                waiting = pending.setdefault(key, Batch(key, spec.table, {}, batch.offsets[:0]))
                _merge_counts(waiting, batch)
                out = through(chain)
                if out is not None:
                    yield _joined(pending.pop(key), out)
        for key, chain in joins.items():
            out = through(chain, final=True)
            if out is not None:
                spec, _ = wanted[key]
                yield _joined(pending.pop(key, Batch(key, spec.table, {}, out.offsets)), out)
        self._record_damage(stats, s)

    # ------------------------------------------------------------------------------- context
    def context(self) -> LogContext:
        """The vehicle's ``STATUSTEXT`` (with its severity) as messages, its ``HEARTBEAT``'s
        mode changes (named by pymavlink) and arming changes (``base_mode`` bit 128), and
        ``VIBRATION`` (m/s^2, clipping counts of the three accelerometers) as vibration."""
        s = self._surveyed()
        out = LogContext(s.base)
        self._held = HeldClock(s.segments[0].stamp_to_utc_ns if s.segments else 0)
        beats: list[tuple[I64, np.ndarray]] = []
        vibe: list[dict[str, np.ndarray]] = []
        for p in scan_blocks(self.file, self.dialect, ScanStats()):
            mine = (p.flag == VALID) & (p.source == s.vehicle)
            self._update_held(p, mine)
            for name in ("STATUSTEXT", "HEARTBEAT", "VIBRATION"):
                mdef = self.dialect.by_name(name)
                if mdef is None:
                    continue
                idx = np.flatnonzero(mine & (p.msgid == mdef.msgid))
                if not len(idx):
                    continue
                rec = decode(p, idx, mdef)
                t, _ = self._times(p, idx, rec, "time_usec" if name == "VIBRATION" else None)
                if name == "STATUSTEXT":
                    severity = [int(v) for v in rec["severity"]]
                    out.events.add(t, EventKind.MESSAGE, decode_text(rec["text"]), name, severity)
                elif name == "HEARTBEAT":
                    beats.append((t, rec))
                else:
                    vibe.append(_vibration(t, rec))
        if beats:
            _heartbeat_events(out, beats)
        if vibe:
            out.vibration = {k: np.concatenate([v[k] for v in vibe]) for k in vibe[0]}
        return out

    def _stream_batch(
        self,
        p: Packets,
        mine: npt.NDArray[np.bool_],
        spec: MavStream,
        inst: int,
        key: str,
        extras: Extras,
    ) -> Batch | None:
        mdef = self.dialect.by_name(spec.message)
        if mdef is None:
            return None
        idx = np.flatnonzero(mine & (p.msgid == mdef.msgid))
        if not len(idx):
            return None
        rec = decode(p, idx, mdef)
        keep = instances(spec, rec) == inst
        idx, rec = idx[keep], rec[keep]
        if not len(idx):
            return None
        conv = spec.convert(rec, extras)
        t, how = self._times(p, idx, rec, spec.time_field)
        cols = {"t_ns": t, **conv.columns}
        info = {"time": how, **conv.info}
        return Batch(key, spec.table, cols, p.offset[idx], conv.nulls, None, conv.counters, info)

    def _push_joins(
        self,
        p: Packets,
        mine: npt.NDArray[np.bool_],
        spec: MavStream,
        chain: list[AsofJoin],
        batch: Batch,
        extras: Extras,
    ) -> None:
        """Give each join of ``chain`` its message's packets in a block, and the first the
        stream's rows."""
        for mj, join in zip(spec.joins, chain, strict=True):
            mdef = self.dialect.by_name(mj.message)
            if mdef is None:
                continue
            idx = np.flatnonzero(mine & (p.msgid == mdef.msgid))
            if len(idx):
                rec = decode(p, idx, mdef)
                t, _ = self._times(p, idx, rec, mj.time_field)
                join.push_right(t, mj.convert(rec, extras).columns)
        cols = dict(batch.columns)
        chain[0].push_left(Left(cols.pop("t_ns"), cols, dict(batch.nulls), batch.offsets))

    def _utc(
        self, p: Packets, idx: npt.NDArray[np.intp], rec: np.ndarray, time_field: str
    ) -> tuple[I64, str]:
        """Vehicle time of packets ``idx`` as UTC ns (``time_boot_ms`` or ``time_usec``)."""
        s = self._surveyed()
        segs = np.clip(s.tracker.segment_of(p.offset[idx]), 0, max(len(s.segments) - 1, 0))
        boot_off = np.array(
            [sc.boot_to_utc_ns if sc.boot_to_utc_ns is not None else 0 for sc in s.segments] or [0],
            np.int64,
        )[segs]
        if time_field == "time_boot_ms":
            utc = rec["time_boot_ms"].astype(np.int64) * 1_000_000 + boot_off
            return utc, "time_boot_ms paired per boot segment"
        usec = rec["time_usec"].astype(np.int64)
        epoch = usec >= EPOCH_MIN_US
        k = np.rint((p.stamp_us[idx] * 1000 - usec * 1000) / ROLLOVER_NS).astype(np.int64)
        epoch_utc = usec * 1000 + np.where(epoch, k, 0) * ROLLOVER_NS
        utc = np.where(epoch, epoch_utc, usec * 1000 + boot_off)
        how = "time_usec (UNIX epoch)" if epoch.all() else "time_usec paired per boot segment"
        return utc, how

    def _times(
        self, p: Packets, idx: npt.NDArray[np.intp], rec: np.ndarray, time_field: str | None
    ) -> tuple[I64, str]:
        """``t_ns`` on the file's base for packets ``idx``, and how it was obtained."""
        if time_field is not None:
            utc, how = self._utc(p, idx, rec, time_field)
        else:
            utc = self._held.at(p.offset[idx], p.stamp_us[idx] * 1000)
            how = (
                "no time field: the vehicle time of the preceding timed packet, advanced by "
                "the tlog stamp difference"
            )
        if self._surveyed().base == TimeBase.GPS:
            return utc_to_gps_ns(utc), how
        return utc, how

    def _update_held(self, p: Packets, mine: npt.NDArray[np.bool_]) -> None:
        """Feed the vehicle's timed packets of a block to the held clock."""
        offsets, utc, stamps = [], [], []
        present = set(np.unique(p.msgid[mine]).tolist())
        for msgid, mdef in self._boot_ids.items():
            if msgid in present:
                idx = np.flatnonzero(mine & (p.msgid == msgid))
                t, _ = self._utc(p, idx, decode(p, idx, mdef), "time_boot_ms")
                offsets.append(p.offset[idx])
                utc.append(t)
                stamps.append(p.stamp_us[idx] * 1000)
        if offsets:
            order = np.argsort(np.concatenate(offsets), kind="stable")
            self._held.push(*(np.concatenate(a)[order] for a in (offsets, utc, stamps)))

    # -------------------------------------------------------------------------------- damage
    def _record_damage(self, stats: ScanStats, s: TlogSurvey) -> None:
        dmg = self.damage
        dmg.note(f"MAVLink dialect {self.dialect.name}; X.25 CRC verified on every packet")
        for line in s.decisions():
            dmg.note(line)
        lost = sum(stats.lost_by_source.values())
        dmg.count("packets_framed", stats.packets)
        if lost:
            dmg.count("packets_lost_seq_gaps", lost)
        other = sum(
            c
            for (sender, name, _), c in s.counts.items()
            if sender != s.vehicle and not BY_NAME[name].suffix  # a packet counted once
        )
        if other:
            dmg.count("packets_from_other_senders", other)
            dmg.note(f"{other} convertible packets from senders other than the vehicle ignored")
        s.tracker.note_resets(dmg, reboot="vehicle reboot", clock="time since boot")
        if s.rollover_rows:
            how = " (reference: the tlog stamps)"
            note_week_rollover(dmg, s.rollover_rows, "vehicle UTC values", s.rollover_weeks, how)
        stats.record_garbage(
            dmg, "MAVLink packets", ", resynchronised on the next packet with a valid CRC"
        )
        self._bad_packets(stats)
        stats.record_partial(dmg)

    def _bad_packets(self, stats: ScanStats) -> None:
        name = self.dialect.msg_name
        suspects = [
            m
            for m, bad in stats.bad_crc.items()
            if bad >= 3 and bad >= DIALECT_CRC_SHARE * (bad + stats.valid.get(m, 0))
        ]
        unknown = sum(stats.unknown.values())
        if unknown:
            self.damage.count("packets_unknown_msgid", unknown)
            ids = ", ".join(f"{m} (x{c})" for m, c in sorted(stats.unknown.items())[:10])
            self.damage.note(f"{unknown} packets with msgids not in {self.dialect.name}: {ids}")
        too_many_unknown = unknown >= 3 and unknown >= DIALECT_UNKNOWN_SHARE * stats.packets
        if suspects or too_many_unknown:
            what = ", ".join(f"{name(m)} ({stats.bad_crc[m]} CRC failures)" for m in suspects)
            if too_many_unknown:
                what = ", ".join(
                    filter(None, [what, f"{unknown} packets with ids {self.dialect.name} lacks"])
                )
            self.damage.record(
                Defect(
                    Completeness.BAD_DATA_SKIPPED,
                    f"suspected wrong MAVLink dialect ({self.dialect.name}): {what}",
                    offset=stats.bad_crc_first,
                    messages_lost=sum(stats.bad_crc[m] for m in suspects) or None,
                )
            )
        bad = sum(stats.bad_crc.values())
        if bad:
            self.damage.count("packets_bad_crc", bad)
            per = ", ".join(f"{name(m)} x{c}" for m, c in stats.bad_crc.most_common(10))
            self.damage.record(
                Defect(
                    Completeness.BAD_DATA_SKIPPED,
                    f"{bad} packets failed their CRC check and were skipped ({per})",
                    offset=stats.bad_crc_first,
                    messages_lost=bad,
                )
            )


#: the messages ``context`` reads, as ``--list`` shows them
_CONTEXT = {
    "STATUSTEXT": "events table (context)",
    "HEARTBEAT": "events table (context: mode, arming)",
    "VIBRATION": "vibration table (context)",
}
#: HEARTBEAT ``base_mode``: MAV_MODE_FLAG_SAFETY_ARMED
_ARMED = 128


def _heartbeat_events(out: LogContext, beats: list[tuple[I64, np.ndarray]]) -> None:
    """Mode and arming changes of the vehicle's heartbeats (the first beat states both)."""
    t = np.concatenate([b[0] for b in beats])
    rec = np.concatenate([b[1] for b in beats])
    ahead = forward(t)
    t, rec = t[ahead], rec[ahead]
    base = rec["base_mode"].astype(np.int64)
    custom = rec["custom_mode"].astype(np.int64)
    armed = (base & _ARMED) != 0
    mode_key = custom * 256 + (base & ~_ARMED)
    at = changes(mode_key)
    names = [
        mavlink_mode_name(
            int(rec["type"][i]), int(rec["autopilot"][i]), int(base[i]), int(custom[i])
        )
        for i in at
    ]
    out.events.add(t[at], EventKind.MODE, names, "HEARTBEAT")
    at = changes(armed)
    out.events.add(
        t[at], EventKind.ARMING, ["armed" if armed[i] else "disarmed" for i in at], "HEARTBEAT"
    )


def _vibration(t: I64, rec: np.ndarray) -> dict[str, np.ndarray]:
    """VIBRATION as vibration rows: the levels on IMU 0's row, each accelerometer's clipping
    count on its own row (``clipping_0..2``)."""
    n = len(t)
    levels = {f"vibe_{a}_mps2": rec[f"vibration_{a}"].astype(np.float64) for a in "xyz"}
    return {
        "t_ns": np.tile(t, 3),
        "imu": np.repeat(np.arange(3), n),
        **{k: np.concatenate([v, np.full(2 * n, np.nan)]) for k, v in levels.items()},
        "clip_count": np.concatenate([rec[f"clipping_{i}"].astype(np.float64) for i in range(3)]),
    }


def _wanted(selections: Sequence[Selection]) -> dict[str, tuple[MavStream, int]]:
    out: dict[str, tuple[MavStream, int]] = {}
    for sel in selections:
        name, _, rest = sel.key.partition("[")
        spec = BY_NAME.get(name)
        if spec is not None:
            out[sel.key] = (spec, int(rest.rstrip("]")) if rest else spec.instance)
    return out


def _merge_counts(held: Batch, batch: Batch) -> None:
    for name, n in batch.counters.items():
        held.counters[name] = held.counters.get(name, 0) + n
    for name, value in batch.info.items():
        held.info.setdefault(name, value)


def _joined(batch: Batch, out: Left) -> Batch:
    cols = {"t_ns": out.t, **out.columns}
    return Batch(
        batch.key, batch.table, cols, out.offsets, out.nulls, None, batch.counters, batch.info
    )
