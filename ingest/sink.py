"""One canonical table being written: time base, frames, hygiene, plausibility, audit, Parquet.

A ``TableSink`` receives its stream's batches (from one or several files) and, per batch:
converts ``t_ns`` to the dataset's time base; converts FLU/ENU vectors to FRD/NED; passes the
rows through ``StreamCleaner`` (reorder, duplicates, clock steps). A companion stream (the
GNSS velocity of the fixes) is cleaned alongside and joined by time (``ingest.companion``).
Final rows gather into blocks of ``block_rows``. The first block decides units and the IMU mounting
(``ingest.plausibility``) before anything is written, so the Parquet provenance can record
those decisions; every block is then scaled/rotated, audited (``StreamAudit``) and appended
through ``TableWriter``.

The magnetometer (``mag``) follows the IMU: its blocks wait until the IMU sink has decided its
mounting, then get the same rotation, so the field and the specific force share one body
frame (``follow``).
"""

from __future__ import annotations

import contextlib
import logging
from pathlib import Path
from typing import Any

import numpy as np
import pyarrow as pa

from navreplay.ingest.audit import StreamAudit
from navreplay.ingest.companion import TOLERANCE_NS, Companion
from navreplay.ingest.config import DatasetConfig
from navreplay.ingest.frames import MAG, flu_to_frd, rotate_imu
from navreplay.ingest.hygiene import Rows, StreamCleaner
from navreplay.ingest.plausibility import GnssDecision, ImuDecision, decide_gnss, decide_imu
from navreplay.ingest.readers.base import Batch
from navreplay.ingest.schema import TableName, from_columns, spec
from navreplay.ingest.select import TablePlan
from navreplay.ingest.tables import Provenance, SourceFile, TableWriter
from navreplay.ingest.timebase import TimeBase, convert

log = logging.getLogger(__name__)

_VELOCITY = ("vel_n_mps", "vel_e_mps", "vel_d_mps", "speed_acc_mps")
#: the columns a row needs, all finite, for a filter to use it
USABLE: dict[TableName, tuple[str, ...]] = {
    TableName.IMU: (
        "acc_x_mps2",
        "acc_y_mps2",
        "acc_z_mps2",
        "gyro_x_radps",
        "gyro_y_radps",
        "gyro_z_radps",
    ),
    TableName.GNSS: ("lat_deg", "lon_deg", "alt_m"),
}
#: above this fraction of unusable rows a table gets a warning
UNUSABLE_WARN_FRACTION = 0.5


class TableSink:
    """Everything between a stream's batches and its Parquet file.

    Args:
        plan: the table and the stream feeding it.
        out_dir: directory of the (temporary) dataset being written.
        base: the dataset's time base.
        sources: source files for the provenance (name and sha256).
        config: the dataset descriptor (sensor units and mounting), or None.
        params: parameters recorded in the provenance hash.
        window_ns, strict, block_rows: hygiene and blocking.
        stack: the ExitStack that owns the writer (closed by the caller, atomically).
    """

    def __init__(
        self,
        plan: TablePlan,
        out_dir: Path,
        *,
        base: TimeBase,
        sources: tuple[SourceFile, ...],
        config: DatasetConfig,
        params: dict[str, Any],
        window_ns: int,
        strict: bool,
        block_rows: int,
        stack: contextlib.ExitStack,
    ) -> None:
        self.plan = plan
        self.table = plan.table
        self.path = out_dir / f"{plan.table.value}.parquet"
        self.base = base
        self.sources = sources
        self.config = config
        self.params = params
        self.block_rows = block_rows
        self.stack = stack
        key = spec(plan.table).key
        self.cleaner = StreamCleaner(
            plan.key, window_ns, strict=strict, secondary=key[1] if len(key) > 1 else None
        )
        self.audit = StreamAudit()
        self.counters: dict[str, int] = {}
        self.info: dict[str, str] = {}
        self.conversions: list[str] = []
        self.imu: ImuDecision | None = None
        self.gnss: GnssDecision | None = None
        self.companion = (
            Companion(plan.companion.key, _VELOCITY, window_ns, strict=strict)
            if plan.companion is not None
            else None
        )
        self.unusable_rows = 0  # rows a filter cannot use (``USABLE``): NaN/inf in a key column
        self.leader: TableSink | None = None  # the IMU sink whose mounting this one follows
        self.mounting_note = ""
        self._mag_rotation: np.ndarray | None = None
        self._block: list[Rows] = []
        self._block_len = 0
        self._writer: TableWriter | None = None
        self._last_path = Path()

    def follow(self, imu: TableSink) -> None:
        """Rotate this table's vectors (the magnetometer's) by ``imu``'s mounting decision."""
        self.leader = imu

    def _waiting_for_leader(self) -> bool:
        return self.leader is not None and self.leader._writer is None

    def push(
        self,
        batch: Batch,
        path: Path,
        source_base: TimeBase,
        frame: str | None,
        *,
        companion: bool = False,
    ) -> None:
        """Take a batch of the table's stream (or, with ``companion``, of its companion)."""
        self._last_path = path
        if companion:
            assert self.companion is not None
            cols = batch.columns
            if source_base != self.base:
                cols["t_ns"] = convert(cols["t_ns"], source_base, self.base)
            note = f"{self.table.value}: velocity {batch.info.get('velocity', 'as recorded')}"
            if note not in self.conversions:
                self.conversions.append(note)
            self.companion.push(Rows(cols, batch.offsets, dict(batch.nulls)), path)
            if self._block_len >= self.block_rows:
                self._flush()
            return
        for name, n in batch.counters.items():
            self.counters[name] = self.counters.get(name, 0) + n
        for name, value in batch.info.items():
            self.info.setdefault(name, value)
        cols = batch.columns
        if source_base != self.base:
            cols["t_ns"] = convert(cols["t_ns"], source_base, self.base)
        frame = batch.frame or frame
        if self.table in (TableName.IMU, TableName.MAG) and self.config.imu.frame != "auto":
            frame = self.config.imu.frame  # the descriptor knows better than the log
        if frame in ("flu", "enu"):
            changed = flu_to_frd(cols, self.table.value)
            note = f"{self.table.value}: {frame.upper()} -> {'FRD' if frame == 'flu' else 'NED'}"
            if changed and note not in self.conversions:
                self.conversions.append(note)
        out = self.cleaner.push(Rows(cols, batch.offsets, dict(batch.nulls)), path)
        self._add(out)

    def _add(self, rows: Rows, *, final: bool = False) -> None:
        if len(rows):
            self._block.append(rows)
            self._block_len += len(rows)
        if self._block_len >= self.block_rows and not final and not self._waiting_for_leader():
            self._flush()

    def finish(self) -> int:
        """Flush everything; returns the number of rows written."""
        self._add(self.cleaner.finish(self._last_path), final=True)
        if self.companion is not None:
            self.companion.finish(self._last_path)
        self._flush(final=True)
        if self.companion is not None:
            self.companion.discard_rest()
        if self._writer is None:
            self._open()
        return self.audit.rows

    def _flush(self, *, final: bool = False) -> None:
        if not self._block_len:
            return
        rows = Rows.concat(self._block)
        self._block, self._block_len = [], 0
        if self.companion is not None:
            rows = self._ready_for_join(rows, final=final)
            if not len(rows):
                return
            self.companion.join(rows, final=final and not self._block_len)
        if self._writer is None:
            self._decide(rows)
            self._open()
        if self.imu is not None:
            self.imu.apply(rows.columns)
        if self.gnss is not None:
            self.gnss.apply(rows.columns)
        if self._mag_rotation is not None:
            rotate_imu(rows.columns, self._mag_rotation, (MAG,))
        self.audit.observe(rows.columns, rows.offsets)
        needed = [rows.columns[c] for c in USABLE.get(self.table, ()) if c in rows.columns]
        if needed:
            ok = np.logical_and.reduce([np.isfinite(c) for c in needed])
            self.unusable_rows += int(len(ok) - np.count_nonzero(ok))
        assert self._writer is not None
        self._writer.write(self._arrow(rows))

    def _ready_for_join(self, rows: Rows, *, final: bool) -> Rows:
        """Rows whose companion rows have all arrived; the rest wait in the block (up to 4
        blocks, after which the join proceeds with what has arrived)."""
        assert self.companion is not None
        wm = self.companion.watermark
        if final or self._block_len + len(rows) >= 4 * self.block_rows:
            return rows
        cut = 0 if wm is None else int(np.searchsorted(rows.t, wm - TOLERANCE_NS, side="right"))
        if cut < len(rows):
            self._block = [rows.take(np.arange(cut, len(rows)))]
            self._block_len = len(rows) - cut
        return rows.take(np.arange(cut))

    def _decide_mag(self) -> None:
        """The IMU's mounting decision, taken over for the magnetic field."""
        imu = None if self.leader is None else self.leader.imu
        if imu is None:
            self.mounting_note = "none (no IMU table to follow)"
        elif imu.mounting_source == "none":
            self.mounting_note = "none (the IMU needed none)"
        else:
            rpy = ", ".join(f"{a:.2f}" for a in imu.mounting_rpy_deg)
            self.mounting_note = f"the IMU's ({imu.mounting_source}): roll, pitch, yaw {rpy} deg"
            self._mag_rotation = imu.c_body_sensor

    def _decide(self, rows: Rows) -> None:
        if self.table == TableName.IMU:
            self.imu = decide_imu(rows.columns, self.config.imu, self._last_path, self.plan.key)
        elif self.table == TableName.GNSS:
            self.gnss = decide_gnss(rows.columns, self.config.gnss, self._last_path, self.plan.key)
        elif self.table == TableName.MAG:
            self._decide_mag()

    def _open(self) -> None:
        extra = {
            "stream": self.plan.key,
            "msgtype": self.plan.sources[0].stream.msgtype,
            "time_base": self.base.value,
            "frame_conversions": "; ".join(self.conversions) or "none",
        }
        for decision in (self.imu, self.gnss):
            if decision is not None:
                extra.update(decision.provenance)
        if self.table == TableName.MAG:
            extra["mag_mounting"] = self.mounting_note or "none (no rows)"
        prov = Provenance.create(self.table, sources=self.sources, params=self.params, extra=extra)
        self._writer = self.stack.enter_context(TableWriter(self.path, self.table, prov))

    def _arrow(self, rows: Rows) -> pa.Table:
        columns: dict[str, Any] = {}
        for name, values in rows.columns.items():
            mask = rows.nulls.get(name)
            if mask is not None and mask.any():
                columns[name] = pa.array(values, mask=mask, from_pandas=False)
            else:
                columns[name] = values
        return from_columns(self.table, columns)

    def report(self, gap_factor: float, file_names: list[str]) -> dict[str, Any]:
        out: dict[str, Any] = {
            "stream": self.plan.key,
            "msgtype": self.plan.sources[0].stream.msgtype,
            "selection": self.plan.reason,
            "alternatives": list(self.plan.alternatives),
            "files": [file_names[s.file_index] for s in self.plan.sources],
            "time_base": self.base.value,
            "frame_conversions": self.conversions,
            "hygiene": self.cleaner.counts.to_json(),
            "stats": self.audit.report(gap_factor),
            "counters": dict(sorted(self.counters.items())),
            "info": self.info,
        }
        if self.companion is not None:
            out["companion"] = self.companion.report()
        if self.table == TableName.MAG:
            out["mounting"] = self.mounting_note or "none (no rows)"
        if self.imu is not None:
            out["plausibility"] = self.imu.report
        if self.gnss is not None:
            out["plausibility"] = self.gnss.report
        return out

    @property
    def mounting_rpy_deg(self) -> tuple[float, float, float] | None:
        return None if self.imu is None else self.imu.mounting_rpy_deg
