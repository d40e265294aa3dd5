"""``navreplay ingest`` as a pure function: logs + descriptor + options -> a tables directory.

``ingest(logs, out_dir, ...)`` detects each log's format from its content, opens its reader,
chooses a stream per canonical table (``ingest.select``), puts every stream on one time base
(``ingest.timebase.reconcile``), and streams each through a ``TableSink`` (frames, hygiene,
plausibility, audit, Parquet). The output directory holds ``<table>.parquet`` for each table
with a stream, ``meta.json`` (``ingest.meta``) and ``ingest_report.json`` (the audit), and
appears atomically (``ingest.atomic.atomic_directory``): on any error nothing is left at
``out_dir`` and an earlier directory there is untouched.

Memory is bounded by the readers' chunk size, the reorder window and ``block_rows``; no log
is ever loaded whole. Files are read one after the other in order of their first timestamp,
so a stream split over several files (a split bag) continues across them.

``inspect(logs, ...)`` is what ``--list`` prints: every file's inventory and the selection.

``ingest_report.json`` (also ``meta.json``'s ``audit``)::

    package_version, options {strict, reorder_window_s, gap_factor}
    time_base {base, leap_seconds, decisions[], checks[],      cross-file overlap checks
               alignment[] {streams, signal, lag_s, correlation, overlap_s, speed_ratio},
                                                  speed-signal lags (ingest.alignment)
               gnss_check {against, files, status, lag_s, median_m_at_lag,
                           median_m_at_zero, epochs, motion_m}}
                                  gnss_obs positions vs the fixes (ingest.gnss.fixcheck)
    files[]   {name, format, variant, streams[] (the inventory), inventory_notes[],
               verification (the checksums the format has, or "unverified: ..."),
               completeness[] ("complete", "truncated", "corrupt_chunks_skipped",
                               "duplicated_copy_dropped", "implausible_values", ...),
               defects[] {kind, reason, offset, messages_lost, messages_recovered,
                          time_range_ns, bytes_skipped}, notes[], counters{}}
    tables{}  {stream, msgtype, selection, alternatives[], files[], time_base,
               frame_conversions[], counters{} (time_from_log, no_fix, payloads_malformed_...),
               info{} (frame_id ...),
               hygiene {rows_in, rows_out, reordered, dropped_late(+offsets),
                        duplicates_exact_dropped, duplicates_conflicting_dropped(+offsets),
                        clock_steps_backward[], duplicated_copies[]},
               stats {rows, first/last_t_ns, duration_s, rate_hz, median_dt_ms, jitter_ms,
                      max_dt_ms, gaps {threshold_ms, count, total_s, longest_s, first[]},
                      segments[], nonfinite{column: {nan, inf}},
                      implausible{column: {count, limit_abs}}},
               plausibility {...} (imu: rest, gravity, gyro bias, mounting; gnss: ranges),
               companion {...} (gnss velocity join)}
    limits[]  {table, code, reason}   what the tables cannot give an INS/GNSS replay
                                      (ingest.limits; logged as warnings)
    warnings[]
"""

from __future__ import annotations

import contextlib
import logging
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from navreplay.ingest.alignment import Alignment, check_tables, fix_latency
from navreplay.ingest.atomic import atomic_directory, atomic_write_json
from navreplay.ingest.config import DatasetConfig
from navreplay.ingest.context import LogContext, write_context
from navreplay.ingest.damage import Completeness, DamageLog, Defect
from navreplay.ingest.detect import Detected, Format, detect
from navreplay.ingest.errors import IngestError, PlausibilityError
from navreplay.ingest.limits import find_limits
from navreplay.ingest.meta import DatasetMeta, SensorMeta, SourceRecord, write_meta
from navreplay.ingest.platform import resolve as resolve_platform
from navreplay.ingest.readers import open_reader
from navreplay.ingest.readers.base import Inventory, LogReader, ReadContext, Selection
from navreplay.ingest.readers.ros.rosmsg import DefinitionError
from navreplay.ingest.schema import TableName
from navreplay.ingest.select import TablePlan, select_streams
from navreplay.ingest.sink import UNUSABLE_WARN_FRACTION, USABLE, TableSink
from navreplay.ingest.tables import SourceFile, package_version, sha256_file
from navreplay.ingest.timebase import TimeBase, reconcile
from navreplay.ingest.typed import to_plain

log = logging.getLogger(__name__)

REPORT_NAME = "ingest_report.json"


@dataclass(frozen=True)
class IngestOptions:
    """Knobs of one ingest (``params.yaml`` ``ingest`` section plus CLI flags).

    Attributes:
        strict: every recoverable defect is an error.
        reorder_window_s: the reorder window W (catalogue case 29).
        gap_factor: a gap is longer than this many median sample periods.
        format: force a format instead of detecting it.
        block_rows: rows per Parquet block (and per first-block plausibility check).
    """

    strict: bool = False
    reorder_window_s: float = 1.0
    gap_factor: float = 5.0
    format: Format | None = None
    block_rows: int = 131_072


@dataclass(frozen=True)
class IngestResult:
    """What ``ingest`` wrote: the directory, rows per table and the report."""

    out_dir: Path
    tables: dict[str, int]
    report: dict[str, Any] = field(repr=False)


@dataclass
class _Log:
    detected: Detected
    damage: DamageLog
    reader: LogReader
    inventory: Inventory


def _open_logs(
    logs: Sequence[Path],
    config: DatasetConfig | None,
    config_dir: Path | None,
    options: IngestOptions,
) -> list[_Log]:
    opened: list[_Log] = []
    found = []
    for path in logs:
        detected = detect(path)
        if options.format is not None and detected.format != options.format:
            detected = Detected(Path(path), options.format, (Path(path),))
        found.append(detected)
    for detected in found:
        damage = DamageLog(detected.path, strict=options.strict)
        ctx = ReadContext(damage, config=config, config_dir=config_dir, siblings=tuple(found))
        reader = open_reader(detected, ctx)
        opened.append(_Log(detected, damage, reader, reader.inventory()))
    return opened


def inspect(
    logs: Sequence[Path],
    *,
    config: DatasetConfig | None = None,
    config_dir: Path | None = None,
    options: IngestOptions | None = None,
) -> tuple[list[Inventory], dict[TableName, TablePlan]]:
    """Inventories of ``logs`` and the stream each table would get (for ``--list``)."""
    opened = _open_logs(logs, config, config_dir, options or IngestOptions())
    inventories = [o.inventory for o in opened]
    for o in opened:
        o.reader.close()
    return inventories, select_streams(inventories, config, check_required=False)


def ingest(
    logs: Sequence[Path],
    out_dir: Path,
    *,
    config: DatasetConfig | None = None,
    config_dir: Path | None = None,
    options: IngestOptions | None = None,
    params: dict[str, Any] | None = None,
) -> IngestResult:
    """Convert ``logs`` (one drive) into canonical tables under ``out_dir``.

    Args:
        logs: log files or rosbag2 directories.
        out_dir: output directory; replaced atomically.
        config: the dataset descriptor (topic overrides, sensor metadata, CSV mappings).
        config_dir: the descriptor's folder (its relative paths resolve against it).
        options: strictness, reorder window, gap factor, forced format.
        params: parameter values recorded (hashed) in each table's provenance.

    Raises:
        UnsupportedFormatError: a log is empty, not a log, or has no reader.
        CorruptLogError: damage that cannot be recovered, or any defect under ``strict``.
        PlausibilityError: implausible units without an override in the descriptor.
        ConfigError, IngestError: a configured or required stream is missing, or time bases
            cannot be reconciled.
    """
    if not logs:
        raise ValueError("ingest needs at least one log")
    options = options or IngestOptions()
    config = config or DatasetConfig(id=_dataset_id(out_dir))
    opened = _open_logs(logs, config, config_dir, options)
    try:
        return _ingest(opened, Path(out_dir), config, options, params or {})
    finally:
        for o in opened:
            o.reader.close()


def _ingest(
    opened: list[_Log],
    out_dir: Path,
    config: DatasetConfig,
    options: IngestOptions,
    params: dict[str, Any],
) -> IngestResult:
    inventories = [o.inventory for o in opened]
    plans = select_streams(inventories, config)
    if not plans:
        why = [f"{s.key}: {s.detail}" for inv in inventories for s in inv.streams if s.detail]
        raise IngestError(
            "no stream in the logs can fill a canonical table",
            path=opened[0].detected.path,
            hint="; ".join(why[:5]) or "see `navreplay ingest --list`",
        )
    used = [q for p in plans.values() for q in (p, p.companion) if q is not None]
    bases = [(q.key, s.stream.time_base) for q in used for s in q.sources]
    utc_starts = [
        s.stream.start_ns
        for q in used
        for s in q.sources
        if s.stream.time_base == TimeBase.UTC and s.stream.start_ns is not None
    ]
    recon = reconcile(
        bases, requested=config.time_base, sample_utc_ns=min(utc_starts, default=None)
    )
    sources = tuple(SourceFile(o.detected.path.name, sha256_file(o.detected.path)) for o in opened)
    names = [o.detected.path.name for o in opened]
    window_ns = round(options.reorder_window_s * 1e9)
    warnings: list[str] = []
    with atomic_directory(out_dir) as tmp, contextlib.ExitStack() as stack:
        sinks = {
            table: TableSink(
                plan,
                tmp,
                base=recon.base,
                sources=tuple(sources[i] for i in sorted(_file_indices(plan))),
                config=config,
                params={"ingest": to_plain(options), "params": params},
                window_ns=window_ns,
                strict=options.strict,
                block_rows=options.block_rows,
                stack=stack,
            )
            for table, plan in plans.items()
        }
        _follow_imu(sinks)
        for index in _file_order(opened):
            o = opened[index]
            routes = {
                q.key: (sinks[t], s.stream, q is not p)
                for t, p in plans.items()
                for q in (p, p.companion)
                if q is not None
                for s in q.sources
                if s.file_index == index
            }
            if not routes:
                continue
            selections = [Selection(k, sink.table) for k, (sink, _, _) in routes.items()]
            for batch in o.reader.read(selections):
                sink, stream, companion = routes[batch.key]
                sink.push(
                    batch, o.detected.path, stream.time_base, stream.frame, companion=companion
                )
        _check_definitions(sinks, opened)
        rows = {t.value: sink.finish() for t, sink in sinks.items()}
        stack.close()
        _report_copies(sinks, opened, warnings)
        _check_usable(sinks, opened, warnings)
        _report_implausible(sinks, opened, warnings)
        _note_empty(rows, plans, warnings)
        checks = _cross_file_checks(sinks, names, warnings)
        gnss_check = _gnss_check(tmp, sinks, names, warnings, options)
        aligned = check_tables(tmp, [t for t, n in rows.items() if n > 1])
        checks += [a.text() for a in aligned]
        for a in aligned:
            if a.suspicious:
                warnings.append(f"time bases disagree: {a.text()}")
                log.warning("time bases disagree: %s", a.text())
        context_rows = _write_context(
            tmp,
            opened,
            recon.base,
            sources,
            {"ingest": to_plain(options), "params": params},
            warnings,
        )
        rows |= context_rows
        report = _report(opened, plans, sinks, recon, options, warnings, names)
        limits = find_limits(tmp, report["tables"], inventories)
        report["limits"] = [lim.to_json() for lim in limits]
        for lim in limits:
            log.warning("%s: %s", lim.table, lim.reason)
        report["time_base"] |= {"checks": checks, "alignment": [a.to_json() for a in aligned]}
        report["context"] = context_rows
        if gnss_check is not None:
            report["time_base"]["gnss_check"] = gnss_check
        meta = DatasetMeta(
            dataset=config.id,
            time_base=recon.base.value,
            sources=tuple(
                SourceRecord(src.name, src.sha256, o.detected.format.value)
                for src, o in zip(sources, opened, strict=True)
            ),
            tables=rows,
            sensors=_sensors(
                config, sinks, inventories, _fix_latency(config, aligned, rows, checks)
            ),
            frame_conversions=tuple(c for s in sinks.values() for c in s.conversions)
            + _mounting_note(sinks),
            audit=report,
        )
        write_meta(tmp, meta)
        atomic_write_json(tmp / REPORT_NAME, report)
    return IngestResult(out_dir, rows, report)


def _note_empty(
    rows: dict[str, int], plans: dict[TableName, TablePlan], warnings: list[str]
) -> None:
    for t, n in rows.items():
        if n == 0:
            warnings.append(f"table {t} ({plans[TableName(t)].key}) is empty")
            log.warning("table %s (%s) is empty", t, plans[TableName(t)].key)


def _write_context(
    tmp: Path,
    opened: list[_Log],
    base: TimeBase,
    sources: tuple[SourceFile, ...],
    params: dict[str, Any],
    warnings: list[str],
) -> dict[str, int]:
    """Write each file's messages, modes, arming, events and vibration
    (``LogReader.context``); returns the rows per table. They are context, not data a filter
    needs: a file whose context cannot be read is noted and left out, never a reason to fail
    the ingest."""
    out: list[tuple[str, LogContext]] = []
    for o in opened:
        name = o.detected.path.name
        try:
            found = o.reader.context()
        except Exception as err:  # context only: said in the audit, never a failed ingest
            what = f"{type(err).__name__}: {err}"
            warnings.append(
                f"{name}: its messages, modes and vibration cannot be read ({what}); the "
                "sensor tables are not affected"
            )
            log.warning("%s: context not read: %s", name, what)
            continue
        if found is not None:
            out.append((name, found))
    written, notes = write_context(tmp, out, base, sources, params)
    warnings += notes
    return written


def _follow_imu(sinks: dict[TableName, TableSink]) -> None:
    """The magnetometer gets the IMU's mounting rotation (one body frame for both)."""
    if TableName.MAG in sinks and TableName.IMU in sinks:
        sinks[TableName.MAG].follow(sinks[TableName.IMU])


#: what each format lets ingest verify; a format not listed has no checksums at all
CHECKSUMS: dict[Format, str] = {
    Format.TLOG: "X.25 CRC of every MAVLink packet, checked",
    Format.MCAP: "CRC-32 of every chunk that carries one, checked",
    Format.NMEA: "checksum of every sentence that carries one, checked",
}
UNVERIFIED = (
    "unverified: the format has no checksums, so bit errors change values undetected; only "
    "plausibility checks apply (time order, physical magnitudes: see each table's hygiene and "
    "stats.implausible)"
)


def _verification(fmt: Format) -> str:
    return CHECKSUMS.get(fmt, UNVERIFIED)


def _report_implausible(
    sinks: dict[TableName, TableSink], opened: list[_Log], warnings: list[str]
) -> None:
    """Values beyond physical limits (``ingest.audit.LIMITS``) are a defect of the file they
    came from: bit damage, most likely, where the format has no checksums; samples out of time
    order in such a file get a warning too."""
    for t, sink in sinks.items():
        o = opened[sink.plan.sources[0].file_index]
        h = sink.cleaner.counts
        disorder = h.reordered + h.dropped_late + len(h.steps)
        if disorder and o.detected.format not in CHECKSUMS:
            text = (
                f"{o.detected.path.name}: table {t.value} ({sink.plan.key}): {disorder} samples "
                "out of time order (re-sorted, dropped late, clock steps) in a file without "
                "checksums: damaged timestamps are possible; see the table's hygiene"
            )
            warnings.append(text)
            log.warning("%s", text)
        over = sink.audit.implausible
        if not over:
            continue
        listed = ", ".join(f"{n} {k}" for k, n in sorted(over.items()))
        why = (
            "corrupt values (the format has no checksums: bit damage?)"
            if o.detected.format not in CHECKSUMS
            else "corrupt or mis-scaled values"
        )
        text = (
            f"{o.detected.path.name}: table {t.value} ({sink.plan.key}) holds values beyond "
            f"physical limits ({listed}): {why}; kept as they are, check them before use"
        )
        warnings.append(text)
        o.damage.record(Defect(Completeness.IMPLAUSIBLE_VALUES, text))


def _check_usable(
    sinks: dict[TableName, TableSink], opened: list[_Log], warnings: list[str]
) -> None:
    """An IMU or GNSS table none of whose rows a filter could use (NaN or inf in a column every
    row needs) is refused; one mostly so gets a warning with the count."""
    for t, sink in sinks.items():
        rows, bad = sink.audit.rows, sink.unusable_rows
        if not rows or not bad:
            continue
        needed = ", ".join(USABLE[t])
        if bad == rows:
            raise PlausibilityError(
                f"every one of the {rows} {t.value} rows has NaN or inf in {needed}: the "
                "stream holds no usable sample",
                path=opened[sink.plan.sources[0].file_index].detected.path,
                record=f"stream {sink.plan.key}",
                hint="check the stream's columns (the csv mapping or topic in dataset.yaml) "
                "or select another stream; no filter can run on it",
            )
        if bad > UNUSABLE_WARN_FRACTION * rows:
            text = (
                f"table {t.value} ({sink.plan.key}): {bad} of {rows} rows "
                f"({100 * bad / rows:.0f} %) have NaN or inf in {needed}; the filters skip them"
            )
            warnings.append(text)
            log.warning("%s", text)


def _report_copies(
    sinks: dict[TableName, TableSink], opened: list[_Log], warnings: list[str]
) -> None:
    """A duplicated copy of a log found by the streams' hygiene becomes one defect of its file
    (the earliest offset any stream saw it at) and a warning, instead of a second segment."""
    by_path = {str(o.detected.path): o for o in opened}
    by_path |= {str(f): o for o in opened for f in o.detected.files}
    found: dict[str, list[tuple[str, int, int]]] = {}
    for t, sink in sinks.items():
        for c in sink.cleaner.counts.copies:
            found.setdefault(c.path, []).append((t.value, c.offset, c.rows_dropped))
    for path, hits in found.items():
        o = by_path.get(path)
        if o is None:
            continue
        at: int | None = min(offset for _, offset, _ in hits)
        if not at:  # a copy follows its original: 0 means the reader gives no record offsets
            at, where = None, " (at an offset the reader does not give)"
        elif o.damage.offsets_are_lines:
            where = f", from line {at} on"
        else:
            where = f", from byte offset {at} on"
        dropped = ", ".join(f"{t} {n}" for t, _, n in hits)
        text = (
            f"{o.detected.path.name}: a duplicated copy of the log{where}: time goes "
            f"back to the start and the rows repeat it exactly; the copy was dropped (rows: "
            f"{dropped}), not read as a second segment"
        )
        warnings.append(text)
        o.damage.record(
            Defect(
                Completeness.DUPLICATED_COPY_DROPPED,
                text,
                offset=at,
                messages_lost=sum(n for _, _, n in hits),
            )
        )


def _check_definitions(sinks: dict[TableName, TableSink], opened: list[_Log]) -> None:
    """A stream whose every payload failed to decode has a wrong definition (case 20)."""
    for sink in sinks.values():
        bad = sink.counters.get("payloads_malformed_dropped", 0)
        if bad and sink.cleaner.counts.rows_in == 0:
            first = sink.plan.sources[0]
            raise DefinitionError(
                f"definition mismatch: none of the {bad} payloads fits {first.stream.msgtype} "
                f"as defined in the log ({sink.info.get('first_malformed_payload', '')})",
                path=opened[first.file_index].detected.path,
                record=f"topic {sink.plan.key}",
                hint="the log's message definition does not describe its payloads; exclude "
                "the topic or fix the definition",
            )


def _cross_file_checks(
    sinks: dict[TableName, TableSink], names: list[str], warnings: list[str]
) -> list[str]:
    """Tables from different files must overlap in time once on one base.

    Streams of one drive recorded by different devices (a bag and a receiver's RINEX) that do
    not overlap at all were most likely put on the wrong clock (a UTC/GPS or boot-time
    mix-up); the gap is reported as a warning with its size.
    """
    spans = []
    for t, sink in sinks.items():
        a = sink.audit
        if a.first_t_ns is not None and a.last_t_ns is not None:
            files = {names[s.file_index] for s in sink.plan.sources}
            spans.append((t.value, files, a.first_t_ns, a.last_t_ns))
    checks: list[str] = []
    for i, (t1, f1, a1, b1) in enumerate(spans):
        for t2, f2, a2, b2 in spans[i + 1 :]:
            if f1 == f2:
                continue
            overlap = min(b1, b2) - max(a1, a2)
            if overlap >= 0:
                checks.append(f"{t1} and {t2} (different files) overlap for {overlap * 1e-9:.1f} s")
                continue
            text = (
                f"{t1} ({', '.join(sorted(f1))}) and {t2} ({', '.join(sorted(f2))}) do not overlap "
                f"in time: {-overlap * 1e-9:.3f} s apart on the dataset's time base; check their "
                "clocks (UTC vs GPS, boot time) and time_base in dataset.yaml"
            )
            checks.append(text)
            warnings.append(text)
            log.warning("%s", text)
    return checks


def _gnss_check(
    tmp: Path,
    sinks: dict[TableName, TableSink],
    names: list[str],
    warnings: list[str],
    options: IngestOptions,
) -> dict[str, Any] | None:
    """Fixes (else the truth) against positions solved from the observations
    (``ingest.gnss.fixcheck``), when the dataset has both; a time offset between them is a
    warning, or an error under strict."""
    obs_sink = sinks.get(TableName.GNSS_OBS)
    fix_sink = sinks.get(TableName.GNSS) or sinks.get(TableName.TRUTH)
    if obs_sink is None or fix_sink is None or not obs_sink.audit.rows or not fix_sink.audit.rows:
        return None
    import pyarrow.parquet as pq

    from navreplay.ingest.gnss import fixcheck

    result = fixcheck.check(pq.read_table(obs_sink.path), pq.read_table(fix_sink.path))
    obs_files = ", ".join(sorted({names[s.file_index] for s in obs_sink.plan.sources}))
    fix_files = ", ".join(sorted({names[s.file_index] for s in fix_sink.plan.sources}))
    against = fix_sink.table.value
    out = {"against": against, "files": {"gnss_obs": obs_files, against: fix_files}}
    out |= result.to_json()
    if result.status in ("offset", "positions_disagree"):
        text = result.message(obs_files, fix_files)
        if options.strict:
            raise IngestError(
                text,
                hint="check each file's time base (time_base in dataset.yaml, the recorder "
                "clock); --strict refuses streams that disagree",
            )
        warnings.append(text)
        log.warning("%s", text)
    return out


def _file_indices(plan: TablePlan) -> set[int]:
    companion = plan.companion.sources if plan.companion is not None else ()
    return {s.file_index for s in (*plan.sources, *companion)}


def _file_order(opened: list[_Log]) -> list[int]:
    big = 1 << 62
    return sorted(range(len(opened)), key=lambda i: (opened[i].inventory.start_ns or big, i))


def _dataset_id(out_dir: Path) -> str:
    parts = [p for p in Path(out_dir).resolve().parts if p not in ("tables", "/")]
    raw = (parts[-1] if parts else "adhoc").lower()
    cleaned = "".join(c if c.isalnum() else "_" for c in raw).strip("_")
    return cleaned if cleaned[:1].isalpha() else f"d_{cleaned}" if cleaned else "adhoc"


def _sensors(
    config: DatasetConfig,
    sinks: dict[TableName, TableSink],
    inventories: list[Inventory],
    latency: tuple[float, str] | None,
) -> SensorMeta:
    imu = sinks.get(TableName.IMU)
    mounting = imu.mounting_rpy_deg if imu is not None else None
    return SensorMeta(
        imu_noise=config.imu.noise,
        lever_arm_m=config.gnss.lever_arm_m,
        imu_mounting_rpy_deg=mounting or (0.0, 0.0, 0.0),
        wheelbase_m=config.vehicle.wheelbase_m,
        platform=resolve_platform(config.platform, (inv.platform for inv in inventories)),
        gnss_latency_s=None if latency is None else latency[0],
        gnss_latency_source="" if latency is None else latency[1],
    )


def _fix_latency(
    config: DatasetConfig, aligned: list[Alignment], rows: dict[str, int], checks: list[str]
) -> tuple[float, str] | None:
    """The fixes' latency against the IMU: declared (``gnss.latency_s``), else measured
    against an onboard estimator on the IMU's clock (``alignment.fix_latency``); the
    decision is one of the time-base checks of the report."""
    if config.gnss.latency_s is not None:
        latency: tuple[float, str] | None = (config.gnss.latency_s, "dataset.yaml gnss.latency_s")
    elif rows.get(TableName.IMU.value, 0) > 0:
        latency = fix_latency(aligned)
    else:
        latency = None
    if latency is not None:
        checks.append(
            f"gnss latency {latency[0]:.3f} s ({latency[1]}): the filters apply each fix at "
            "its stamp minus this (dataset.yaml gnss.latency_s overrides it)"
        )
    return latency


def _mounting_note(sinks: dict[TableName, TableSink]) -> tuple[str, ...]:
    imu = sinks.get(TableName.IMU)
    if imu is None or imu.imu is None or imu.imu.mounting_source == "none":
        return ()
    r, p, y = imu.imu.mounting_rpy_deg
    return (
        f"imu: mounting roll {r:.2f}, pitch {p:.2f}, yaw {y:.2f} deg ({imu.imu.mounting_source})",
    )


def _report(
    opened: list[_Log],
    plans: dict[TableName, TablePlan],
    sinks: dict[TableName, TableSink],
    recon: Any,
    options: IngestOptions,
    warnings: list[str],
    names: list[str],
) -> dict[str, Any]:
    files = []
    for o in opened:
        entry = {
            "name": o.detected.path.name,
            "format": o.detected.format.value,
            "variant": o.detected.variant,
            "streams": [
                {
                    "key": s.key,
                    "msgtype": s.msgtype,
                    "count": s.count,
                    "rate_hz": s.rate_hz,
                    "table": s.table.value if s.table else None,
                    "detail": s.detail,
                }
                for s in o.inventory.streams
            ],
            "inventory_notes": list(o.inventory.notes),
            "verification": _verification(o.detected.format),
        }
        entry.update(o.damage.to_json())
        files.append(entry)
    return {
        "package_version": package_version(),
        "options": {
            "strict": options.strict,
            "reorder_window_s": options.reorder_window_s,
            "gap_factor": options.gap_factor,
        },
        "time_base": {
            "base": recon.base.value,
            "leap_seconds": recon.leap_seconds,
            "decisions": list(recon.decisions),
        },
        "files": files,
        "tables": {t.value: sinks[t].report(options.gap_factor, names) for t in plans},
        "warnings": warnings,
    }
