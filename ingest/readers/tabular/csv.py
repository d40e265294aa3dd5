"""CSV and other delimited text logs, mapped onto canonical tables by ``csv:`` entries of
``dataset.yaml`` (``ingest.config.CsvSource``).

A file with no mapping is still read when its header already uses canonical names (``t_ns``
plus the required columns of one table), which is what navreplay's own CSV exports look like.

Bad input (catalogue cases 18, 19, 21):

- a last line without its newline is a truncated write: it is dropped and reported (E-RECOVER);
- a line with the wrong number of fields, or a value that is not a number (``ERR``), is
  skipped and counted with its line number (E-RECOVER: ``--strict`` makes it an error);
- a repeated header line (a logger restart appending to the file) is skipped and counted;
- a header that names a mapped column twice (``t,ax,ax``) is E-FATAL with the line number;
- the literals ``NaN``, ``nan``, ``inf``, ``-Infinity`` stay NaN/inf (invalid, never null); an
  empty cell is null ("not provided") in a nullable column and NaN otherwise.

Row offsets in batches and defects are 1-based line numbers.
"""

from __future__ import annotations

import re
from collections.abc import Iterator, Sequence
from pathlib import Path

import numpy as np
import numpy.typing as npt
import pyarrow as pa

from navreplay.ingest.config import CsvSource
from navreplay.ingest.detect import Detected, Format
from navreplay.ingest.errors import ConfigError, CorruptLogError, UnsupportedFormatError
from navreplay.ingest.readers._lines import BadLines, listed, partial_line_defect
from navreplay.ingest.readers.base import (
    Batch,
    Inventory,
    LogReader,
    ReadContext,
    Selection,
    StreamInfo,
)
from navreplay.ingest.schema import TableName, spec
from navreplay.ingest.timebase import TimeBase

_UNIT_NS = {"ns": 1, "us": 1_000, "ms": 1_000_000, "s": 1_000_000_000}
_WS = re.compile(r"\s+")


class CsvReader(LogReader):
    """Reader of one delimited text file, for every ``csv:`` mapping that names it."""

    format = Format.CSV
    offsets_are_lines = True

    def __init__(self, detected: Detected, ctx: ReadContext) -> None:
        super().__init__(detected, ctx)
        self.sources = self._sources()

    def _sources(self) -> list[CsvSource]:
        cfg, base = self.ctx.config, self.ctx.config_dir or Path.cwd()
        here = self.file.resolve()
        mapped = [src for src in (cfg.csv if cfg else ()) if (base / src.path).resolve() == here]
        if mapped:
            return mapped
        line, names = self._peek_header(",")
        header = set(names)
        best: tuple[int, TableName] | None = None
        for table in TableName:
            columns = spec(table).columns
            needed = {c.name for c in columns if c.required and not c.nullable}
            matched = len(header & {c.name for c in columns} - {"t_ns"})
            if needed <= header and matched and (best is None or matched > best[0]):
                best = (matched, table)
        if best is not None:
            table = best[1]
            cols = {c.name: c.name for c in spec(table).columns if c.name in header}
            cols.pop("t_ns")
            return [CsvSource(str(self.file), table.value, "t_ns", "ns", cols)]
        hint = (
            "add a `csv:` entry for this file to dataset.yaml (table, time_column, time_unit, "
            "columns) and pass --dataset-config"
        )
        near = _nearest_table(header)
        if near is not None:
            table, missing = near
            raise UnsupportedFormatError(
                f"the header has most of table {table.value}'s columns but lacks "
                f"{', '.join(missing)} (a damaged or renamed column?)",
                path=self.file,
                offset=line,
                record=f"line {line}",
                hint=f"repair the header line, or {hint}",
            )
        shown = ", ".join(names[:8]) + (", ..." if len(names) > 8 else "")
        raise UnsupportedFormatError(
            f"delimited text with no column mapping (header: {shown})",
            path=self.file,
            offset=line,
            record=f"line {line}",
            hint=hint,
        )

    def _peek_header(self, delimiter: str) -> tuple[int, list[str]]:
        """The header's line number and its fields (the first line that is not a comment)."""
        with self.file.open("rb") as fh:
            for number, raw in enumerate(fh, start=1):
                text = raw.decode("utf-8", "replace").strip()
                if text and not text.startswith("#"):
                    return number, [f.strip() for f in text.split(delimiter)]
        return 1, []

    def _time_base(self, src: CsvSource) -> TimeBase:
        if src.time_base is not None:
            return TimeBase(src.time_base)
        declared = self.ctx.config.time_base if self.ctx.config is not None else "auto"
        return TimeBase.RECORDER if declared == "auto" else TimeBase(declared)

    def inventory(self) -> Inventory:
        streams = tuple(
            StreamInfo(
                key=f"csv:{src.table}",
                msgtype="csv",
                count=None,
                start_ns=None,
                end_ns=None,
                table=TableName(src.table),
                time_base=self._time_base(src),
                frame=src.frame,
                detail=", ".join(f"{k}<-{v}" for k, v in src.columns.items()),
            )
            for src in self.sources
        )
        return Inventory(self.path, self.format, streams, ("rows counted while reading",))

    def read(self, selections: Sequence[Selection]) -> Iterator[Batch]:
        keys = {s.key for s in selections}
        chosen = [src for src in self.sources if f"csv:{src.table}" in keys]
        if not chosen:
            return
        delimiter = chosen[0].delimiter
        comment = chosen[0].comment
        lines: list[list[str]] = []
        numbers: list[int] = []
        header: list[str] | None = None
        idx: list[list[int]] = []
        stats = _LineStats()
        with self.file.open("rb") as fh:
            for number, raw in enumerate(fh, start=1):
                if not raw.endswith(b"\n"):
                    stats.partial = number
                    break
                text = raw.decode("utf-8", "replace").strip()
                if not text or text.startswith(comment):
                    stats.comments += 1
                    continue
                fields = _split(text, delimiter)
                if header is None:
                    header = fields
                    idx = [self._indices(src, header, number) for src in chosen]
                    continue
                if fields == header:
                    stats.headers.append(number)
                    continue
                if len(fields) != len(header):
                    stats.bad.add(number, f"{len(fields)} fields, the header has {len(header)}")
                    continue
                lines.append(fields)
                numbers.append(number)
                if len(lines) >= self.ctx.batch_rows:
                    yield from self._batches(chosen, idx, lines, numbers, stats)
                    lines, numbers = [], []
        if header is None:
            raise CorruptLogError("no header line", path=self.file, offset=1)
        if lines:
            yield from self._batches(chosen, idx, lines, numbers, stats)
        self._report(stats)

    def _indices(self, src: CsvSource, header: list[str], line: int) -> list[int]:
        names = [src.time_column, *src.columns.values()]
        out = []
        for name in names:
            hits = [i for i, h in enumerate(header) if h == name]
            if not hits:
                raise ConfigError(
                    f"column {name!r} of the csv mapping is not in the header "
                    f"({', '.join(header)})",
                    path=self.file,
                    record=f"line {line}",
                )
            if len(hits) > 1:
                raise CorruptLogError(
                    f"the header names column {name!r} {len(hits)} times (fields "
                    f"{', '.join(str(h + 1) for h in hits)}): which one is meant is ambiguous",
                    path=self.file,
                    offset=line,
                    record=f"line {line}",
                )
            out.append(hits[0])
        return out

    def _batches(
        self,
        sources: list[CsvSource],
        indices: list[list[int]],
        lines: list[list[str]],
        numbers: list[int],
        stats: _LineStats,
    ) -> Iterator[Batch]:
        line_no = np.asarray(numbers, np.int64)
        for src, idx in zip(sources, indices, strict=True):
            cells = np.array([[row[i] for i in idx] for row in lines], dtype=object)
            t_ns, ok_t = _parse_time(cells[:, 0], src.time_unit)
            values, empty, ok_v = _parse_values(cells[:, 1:])
            ok = ok_t & ok_v
            for r in np.flatnonzero(~ok).tolist():
                bad_col = src.time_column if not ok_t[r] else _first_bad(cells[r, 1:], src)
                stats.bad.add(numbers[r], f"column {bad_col!r} is not a number")
            columns: dict[str, np.ndarray] = {"t_ns": t_ns[ok]}
            nulls: dict[str, npt.NDArray[np.bool_]] = {}
            table_spec = spec(src.table)
            for j, name in enumerate(src.columns):
                spec_col = table_spec.column(name)
                v = values[ok, j] * src.scale.get(name, 1.0)
                e = empty[ok, j]
                if spec_col is not None and pa.types.is_integer(spec_col.type):
                    columns[name] = _to_int(v, spec_col.type.to_pandas_dtype())
                else:
                    columns[name] = v
                if e.any():
                    if spec_col is not None and spec_col.nullable:
                        nulls[name] = e
                    stats.empty_cells += int(e.sum())
            for name, value in src.constants.items():
                const_col = table_spec.column(name)
                const = np.full(int(ok.sum()), value)
                if const_col is not None and pa.types.is_integer(const_col.type):
                    columns[name] = _to_int(const, const_col.type.to_pandas_dtype())
                else:
                    columns[name] = const
            yield Batch(
                key=f"csv:{src.table}",
                table=TableName(src.table),
                columns=columns,
                offsets=line_no[ok],
                nulls=nulls,
                frame=src.frame,
            )

    def _report(self, stats: _LineStats) -> None:
        d = self.damage
        d.count("comment_lines", stats.comments)
        d.count("empty_cells", stats.empty_cells)
        if stats.headers:
            d.count("repeated_header_lines", len(stats.headers))
            d.note(f"repeated header lines skipped at lines {listed(stats.headers)}")
        if stats.bad.lines:
            d.record(stats.bad.defect())
        if stats.partial is not None:
            d.record(partial_line_defect(stats.partial))


def _nearest_table(header: set[str]) -> tuple[TableName, list[str]] | None:
    """The canonical table whose required columns the header has all but one or two of (a
    navreplay export with a damaged header), and those it lacks."""
    best: tuple[int, TableName, list[str]] | None = None
    for table in TableName:
        needed = [c.name for c in spec(table).columns if c.required and not c.nullable]
        missing = [n for n in needed if n not in header]
        have = len(needed) - len(missing)
        if 0 < len(missing) <= 2 and have >= 3 and (best is None or have > best[0]):
            best = (have, table, missing)
    return None if best is None else (best[1], best[2])


class _LineStats:
    def __init__(self) -> None:
        self.comments = 0
        self.empty_cells = 0
        self.headers: list[int] = []
        self.bad = BadLines()
        self.partial: int | None = None


def _split(text: str, delimiter: str) -> list[str]:
    if delimiter == "whitespace":
        return _WS.split(text)
    return [f.strip() for f in text.split(delimiter)]


def _parse_values(
    cells: npt.NDArray[np.object_],
) -> tuple[npt.NDArray[np.float64], npt.NDArray[np.bool_], npt.NDArray[np.bool_]]:
    """Floats, a mask of empty cells, and a per-row mask of rows that parsed."""
    empty = cells == ""
    filled = np.where(empty, "nan", cells)
    try:
        return filled.astype(np.float64), empty, np.ones(len(cells), bool)
    except ValueError:
        pass
    out = np.full(cells.shape, np.nan)
    ok = np.ones(len(cells), bool)
    for r in range(len(cells)):
        try:
            out[r] = [float(x) for x in filled[r]]
        except ValueError:
            ok[r] = False
    return out, empty, ok


def _parse_time(
    cells: npt.NDArray[np.object_], unit: str
) -> tuple[npt.NDArray[np.int64], npt.NDArray[np.bool_]]:
    """Exact decimal -> int64 ns (no float rounding of large epoch values)."""
    scale = _UNIT_NS[unit]
    digits = len(str(scale)) - 1
    t = np.zeros(len(cells), np.int64)
    ok = np.ones(len(cells), bool)
    for r, text in enumerate(cells.tolist()):
        try:
            neg = text.startswith("-")
            whole, _, frac = text.lstrip("+-").partition(".")
            if "e" in text.lower() or not (whole or frac):
                value = round(float(text) * scale)
            else:
                frac_ns = int((frac + "0" * digits)[:digits]) if digits else 0
                value = int(whole or "0") * scale + frac_ns
                value = -value if neg else value
            t[r] = value
        except (ValueError, OverflowError):
            ok[r] = False
    return t, ok


def _first_bad(row: npt.NDArray[np.object_], src: CsvSource) -> str:
    for name, cell in zip(src.columns.values(), row.tolist(), strict=True):
        if cell == "":
            continue
        try:
            float(cell)
        except ValueError:
            return name
    return "?"


def _to_int(values: npt.NDArray[np.float64], dtype: object) -> np.ndarray:
    filled = np.where(np.isfinite(values), values, 0)
    return np.rint(filled).astype(np.dtype(dtype))  # type: ignore[call-overload]
