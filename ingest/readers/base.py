"""The reader interface every log format implements (the damage log they share is
``ingest.damage``).

Developer note: adding a reader
-------------------------------
1. ``ingest/detect.py`` already recognises the format (add a recogniser there if not).
2. Write ``ingest/readers/<family>/<format>.py`` (family: ``ros``, ``mavlink``, ``ulog``,
   ``gnss``, ``tabular``, or a new one) with a subclass of ``LogReader``:

   - ``format`` (and ``offsets_are_lines = True`` for a text format); ``__init__(detected,
     ctx)`` if it needs one: open nothing expensive; ``self.file`` is the (first) file and
     ``self.damage`` the damage log.
   - ``inventory()``: every stream the log holds (``StreamInfo``: key, message type, count,
     first/last time, the canonical table it can feed, time base, frame). ``--list`` prints
     it and the automatic selection (``ingest.select``) chooses from it. Keys are stable
     strings: a ROS topic, ``RAW_IMU[1]`` for a MAVLink instance, ``sensor_combined[0]``.
   - ``read(selections)``: yield ``Batch`` objects for the selected streams, in file order,
     each a chunk of column arrays already named and scaled as the canonical table wants
     (``t_ns`` int64 on the stream's declared time base, SI units, angles in rad,
     lat/lon in deg), in the stream's declared axis ``frame`` (``frd``/``ned`` or ``flu``/
     ``enu``; ``ingest.frames`` converts). Decode straight into arrays: per-message Python
     costs more than the arithmetic (see ``ingest.readers.ros.rosmsg`` for the pattern).
     ``offsets`` gives, per row, the byte offset of its record (or of its enclosing chunk).
   - Damage: call ``ctx.damage.record(Defect(...))`` for every recoverable defect
     (truncation, corrupt chunk, garbage bytes, a trailing partial record); it raises
     ``CorruptLogError`` itself under ``--strict``. Raise ``CorruptLogError`` /
     ``UnsupportedFormatError`` with path and offset for what cannot be recovered, chained
     ``from err``. Never modify the input file.
3. Add one line to ``REGISTRY`` in ``ingest/readers/__init__.py``.

Everything downstream (time-base reconciliation, reorder/duplicate/gap hygiene, frame and
mounting conversion, plausibility checks, the audit, atomic Parquet output) is shared and
needs nothing from the reader beyond this interface.

Time bases: a stream on GPS time declares ``TimeBase.GPS`` (week/TOW already combined with
``ingest.timebase.gps_week_tow_to_ns``); a recorder clock that the reader can pair with GPS
time (MAVLink ``time_boot_ms`` with ``GPS_RAW_INT.time_usec``) should be converted by the
reader and declared GPS; a clock it cannot pair stays ``RECORDER``.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import ClassVar, Self

import numpy as np
import numpy.typing as npt

from navreplay.ingest.arrays import I64
from navreplay.ingest.config import DatasetConfig
from navreplay.ingest.context import LogContext
from navreplay.ingest.damage import DamageLog
from navreplay.ingest.detect import Detected, Format
from navreplay.ingest.platform import UNKNOWN, Platform
from navreplay.ingest.schema import TableName
from navreplay.ingest.timebase import TimeBase


@dataclass(frozen=True)
class ReadContext:
    """What a reader gets besides the file.

    Attributes:
        damage: where the reader records defects (strict handling included).
        batch_rows: a hint for the number of rows per ``Batch``.
        config: the dataset descriptor, if one was given (CSV column mappings, instances).
        config_dir: the descriptor's folder (its relative paths resolve against it).
        siblings: every log of this ingest, the reader's own included, in the order given
            (a RINEX observation or Android raw file finds its navigation files here).
    """

    damage: DamageLog
    batch_rows: int = 65_536
    config: DatasetConfig | None = None
    config_dir: Path | None = None
    siblings: tuple[Detected, ...] = ()


@dataclass(frozen=True)
class StreamInfo:
    """One stream of a log, as ``--list`` shows it and selection sees it.

    Attributes:
        key: stable identifier within the file (ROS topic, ``RAW_IMU[1]``, ...).
        msgtype: message type (``sensor_msgs/msg/Imu``, ``RAW_IMU``, ...).
        count: number of messages, None if unknown without a full pass.
        start_ns: first log time, None if unknown.
        end_ns: last log time, None if unknown.
        table: the canonical table this stream can feed, None if none.
        time_base: the clock ``t_ns`` of this stream's batches counts on.
        frame: axis convention of the batches' vector columns: ``frd``/``ned`` (canonical) or
            ``flu``/``enu`` (REP-103); None when the stream has no vectors.
        instance: sensor instance number for multi-instance sensors, else None.
        detail: anything else worth showing (encoding, frame_id ...).
        role: ``""`` for a stream that can be a table's primary stream; ``velocity`` for a
            GNSS velocity stream joined to the fixes by time (``ingest.sink``).
        refused: why the stream cannot feed the table it otherwise would (``table`` is then
            None; ``ingest.limits`` reports the reason when that table stays empty), e.g. a
            PX4 ``sensor_combined`` logged at 7.8 Hz whose samples integrate 4 ms each.
    """

    key: str
    msgtype: str
    count: int | None
    start_ns: int | None
    end_ns: int | None
    table: TableName | None
    time_base: TimeBase
    frame: str | None = None
    instance: int | None = None
    detail: str = ""
    role: str = ""
    refused: str = ""

    @property
    def rate_hz(self) -> float | None:
        """Mean message rate over the stream's span, None if not computable."""
        if self.count is None or self.start_ns is None or self.end_ns is None:
            return None
        span = self.end_ns - self.start_ns
        if self.count < 2 or span <= 0:
            return None
        return (self.count - 1) / (span * 1e-9)


@dataclass(frozen=True)
class Inventory:
    """Everything a log holds, before conversion.

    Attributes:
        platform: the vehicle kind the log says it was recorded on (``ingest.platform``),
            with its source; unknown for a format that does not say.
    """

    path: Path
    format: Format
    streams: tuple[StreamInfo, ...]
    notes: tuple[str, ...] = ()
    platform: Platform = UNKNOWN

    def stream(self, key: str) -> StreamInfo | None:
        for s in self.streams:
            if s.key == key:
                return s
        return None

    @property
    def start_ns(self) -> int | None:
        starts = [s.start_ns for s in self.streams if s.start_ns is not None]
        return min(starts) if starts else None


@dataclass(frozen=True)
class Selection:
    """A stream chosen to fill a canonical table."""

    key: str
    table: TableName


@dataclass
class Batch:
    """A chunk of rows of one stream, decoded into canonical columns.

    Attributes:
        key: the stream's key.
        table: the canonical table the rows go to.
        columns: canonical column name -> 1-D array, ``t_ns`` (int64) included; floats in SI
            units, vectors in the stream's declared frame.
        offsets: int64 byte offset per row of its record (or enclosing chunk) in the file.
        nulls: column -> boolean mask of rows where the value is "not provided" (null).
        frame: axis convention of this batch's vectors when it overrides the stream's
            (e.g. a ROS ``frame_id`` ending in ``_ned``).
        counters: per-stream counts for the report (``time_from_log``, ``no_fix`` ...).
        info: per-stream facts for the report (``frame_id`` ...); the first value is kept.
    """

    key: str
    table: TableName
    columns: dict[str, np.ndarray]
    offsets: I64
    nulls: dict[str, npt.NDArray[np.bool_]] = field(default_factory=dict)
    frame: str | None = None
    counters: dict[str, int] = field(default_factory=dict)
    info: dict[str, str] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.offsets)


class LogReader(ABC):
    """Base class of every format reader (see the module docstring for the contract).

    Args:
        detected: what ``ingest.detect.detect`` found (format, files, variant).
        ctx: the damage log and read options.
    """

    format: Format
    #: a text format: the offsets of its damage report are line numbers, not bytes
    offsets_are_lines: ClassVar[bool] = False

    def __init__(self, detected: Detected, ctx: ReadContext) -> None:
        self.detected = detected
        self.path = detected.path
        self.ctx = ctx
        self.damage = ctx.damage
        if self.offsets_are_lines:
            self.damage.offsets_are_lines = True

    @property
    def file(self) -> Path:
        """The log's first file (of a single-file format, its only one)."""
        return self.detected.files[0]

    @abstractmethod
    def inventory(self) -> Inventory:
        """Every stream in the log (may scan the file when it has no index)."""

    @abstractmethod
    def read(self, selections: Sequence[Selection]) -> Iterator[Batch]:
        """Yield batches of the selected streams, in file order."""

    def context(self) -> LogContext | None:
        """The log's messages, modes, arming, events and vibration (``ingest.context``), on
        the time base of its streams; None for a format that logs none. Called after
        ``read``."""
        return None

    def close(self) -> None:  # noqa: B027 (optional hook: most readers hold nothing open)
        """Release open files; called once after reading."""

    def __enter__(self) -> Self:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()


def selected_tables(selections: Sequence[Selection]) -> Mapping[str, TableName]:
    """Stream key -> table for a selection list (the form readers look keys up in)."""
    return {s.key: s.table for s in selections}
