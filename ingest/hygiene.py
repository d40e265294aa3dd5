"""Stream hygiene: every stream leaves ingest strictly increasing in ``t_ns``, in bounded memory.

``StreamCleaner`` takes a stream's batches in arrival (file) order and emits rows that are
sorted and unique, applying the catalogue's rules (bad-inputs.md, cases 29-32):

- out of order within the reorder window W (``ingest.reorder_window_s``): re-sorted and
  counted (case 29);
- older than W behind the newest sample seen: dropped and counted, with offsets (case 29);
- a run of at least ``STEP_MIN_SAMPLES`` consecutive samples all older than the window and
  increasing among themselves is a clock step backwards (case 31), not late samples: the
  stream is split there and the later segment re-based to continue one nominal period after
  the last sample before the step, so no negative or zero dt ever leaves ingest; the step,
  its size and the shift are reported;
- equal timestamps (case 30): exact duplicates (every column equal, NaN == NaN) are dropped
  and counted; non-identical ones keep the first arrival and are counted as conflicting;
  a table keyed by time and a second column (``gnss_obs``: ``t_ns``, ``sv``) sorts by both
  and only rows equal in both are duplicates (one epoch holds many satellites);
- a clock step backwards whose first rows repeat rows of the stream's start exactly (time and
  every value) is not a clock step but a duplicated copy of the log (a file concatenated with
  itself, the same file given twice): the copy is dropped, up to where the original ended,
  and reported with its offset and row count instead of becoming a second segment;
- ``--strict`` turns re-sorting, late drops, conflicting duplicates, clock steps and copies
  into a ``CorruptLogError`` naming the file and the record offset.

Rows are held only while they may still be preceded by a late arrival (W of data), plus the
output block being assembled, so memory does not grow with the log.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt

from navreplay.ingest.arrays import I64, Bools
from navreplay.ingest.errors import CorruptLogError

STEP_MIN_SAMPLES = 3
#: rows compared with the stream's first rows to call a step backwards a duplicated copy
COPY_MATCH_ROWS = 8
#: the stream's first rows kept for that comparison (the copy may start a little later: a
#: reader resynchronising after the copy's header loses its first records)
COPY_HEAD_ROWS = 256
_MAX_LISTED = 10


@dataclass
class Rows:
    """Rows of one stream: canonical columns, per-row record offsets and null masks."""

    columns: dict[str, np.ndarray]
    offsets: I64
    nulls: dict[str, Bools] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.offsets)

    @property
    def t(self) -> I64:
        return self.columns["t_ns"]

    def take(self, idx: npt.NDArray[Any]) -> Rows:
        return Rows(
            {k: v[idx] for k, v in self.columns.items()},
            self.offsets[idx],
            {k: v[idx] for k, v in self.nulls.items()},
        )

    @staticmethod
    def concat(parts: list[Rows]) -> Rows:
        parts = [p for p in parts if len(p)]
        if not parts:
            return Rows({}, np.empty(0, np.int64))
        if len(parts) == 1:
            return parts[0]
        names = list(parts[0].columns)
        null_names = sorted({k for p in parts for k in p.nulls})
        return Rows(
            {k: np.concatenate([p.columns[k] for p in parts]) for k in names},
            np.concatenate([p.offsets for p in parts]),
            {
                k: np.concatenate([p.nulls.get(k, np.zeros(len(p), bool)) for p in parts])
                for k in null_names
            },
        )


@dataclass
class TimeStep:
    """A clock step backwards, handled by re-basing what follows."""

    offset: int
    t_ns: int
    step_ns: int
    shift_ns: int
    path: str


@dataclass
class DuplicateCopy:
    """A duplicated copy of the stream's start, dropped (see the module docstring)."""

    offset: int
    t_ns: int
    path: str
    rows_dropped: int = 0


@dataclass
class HygieneCounts:
    rows_in: int = 0
    rows_out: int = 0
    reordered: int = 0
    dropped_late: int = 0
    dropped_late_offsets: list[int] = field(default_factory=list)
    duplicates_exact: int = 0
    duplicates_conflicting: int = 0
    duplicates_conflicting_offsets: list[int] = field(default_factory=list)
    steps: list[TimeStep] = field(default_factory=list)
    copies: list[DuplicateCopy] = field(default_factory=list)

    def to_json(self) -> dict[str, Any]:
        return {
            "duplicated_copies": [
                {"file": c.path, "offset": c.offset, "t_ns": c.t_ns, "rows_dropped": c.rows_dropped}
                for c in self.copies
            ],
            "rows_in": self.rows_in,
            "rows_out": self.rows_out,
            "reordered": self.reordered,
            "dropped_late": self.dropped_late,
            "dropped_late_offsets": self.dropped_late_offsets,
            "duplicates_exact_dropped": self.duplicates_exact,
            "duplicates_conflicting_dropped": self.duplicates_conflicting,
            "duplicates_conflicting_offsets": self.duplicates_conflicting_offsets,
            "clock_steps_backward": [
                {
                    "file": s.path,
                    "offset": s.offset,
                    "t_ns": s.t_ns,
                    "step_s": s.step_ns * 1e-9,
                    "shift_applied_s": s.shift_ns * 1e-9,
                }
                for s in self.steps
            ],
        }


class StreamCleaner:
    """Re-sort, de-duplicate and de-step one stream (see the module docstring).

    Args:
        name: stream name for messages.
        window_ns: the reorder window W in ns.
        strict: raise on any defect that changes or drops data.
        secondary: a column completing the row key (``sv`` for ``gnss_obs``), or None.
    """

    def __init__(
        self, name: str, window_ns: int, *, strict: bool, secondary: str | None = None
    ) -> None:
        self.name = name
        self.secondary = secondary
        self.window_ns = window_ns
        self.strict = strict
        self.counts = HygieneCounts()
        self._pending = Rows({}, np.empty(0, np.int64))
        self._held = Rows({}, np.empty(0, np.int64))  # undecided late run at a batch end
        self._held_path = ""
        self._max_t: int | None = None
        self._shift = 0
        self._nominal_ns: int | None = None
        self._last_out: Rows | None = None
        self._head = Rows({}, np.empty(0, np.int64))  # the stream's first rows, as received
        self._copy_until: int | None = None  # inside a duplicated copy: drop rows up to here
        self._first_index = 0  # arrival index (0 = the stream's first row) of the rows admitted

    def push(self, rows: Rows, path: Path) -> Rows:
        """Add a batch (arrival order); return the rows that are now final (sorted, unique)."""
        self.counts.rows_in += len(rows)
        if not len(rows):
            return self._empty_like(rows)
        if len(self._head) < COPY_HEAD_ROWS and not self._shift and not self.counts.steps:
            need = min(COPY_HEAD_ROWS - len(self._head), len(rows))
            self._head = Rows.concat([self._head, rows.take(np.arange(need))])
        rows.columns["t_ns"] = rows.t + self._shift
        if len(self._held):
            rows = Rows.concat([self._held, rows])
            self._held = Rows({}, np.empty(0, np.int64))
        if self._nominal_ns is None:
            self._nominal_ns = _median_dt(rows.t)
        self._first_index = self.counts.rows_in - len(rows)  # arrival index of rows[0]
        accepted = self._admit(rows, path, final=False)
        return self._emit(accepted, path, final=False)

    def finish(self, path: Path) -> Rows:
        """Flush everything held; returns the last final rows."""
        self._first_index = self.counts.rows_in - len(self._held)
        accepted = self._admit(self._held, path, final=True) if len(self._held) else None
        self._held = Rows({}, np.empty(0, np.int64))
        return self._emit(accepted, path, final=True)

    # ------------------------------------------------------------------------------ admission
    def _admit(self, rows: Rows, path: Path, *, final: bool) -> Rows | None:
        """Drop late samples, re-base clock steps; return admitted rows (arrival order).

        One running maximum serves every decision of a pass (late samples never raise it);
        only a clock step, which shifts what follows, starts a new pass. Cost: O(n) per batch
        plus O(1) per late sample.
        """
        keep = np.ones(len(rows), bool)
        start = self._drop_copy(rows, 0, keep)
        while start < len(rows):
            seg = rows.t[start:]
            prev = self._max_t if self._max_t is not None else int(seg[0])
            before = np.maximum.accumulate(np.concatenate([[prev], seg]))[:-1]
            late = seg < before - self.window_ns
            stop, step_at = len(rows), None
            skip_until = 0
            for i in (np.flatnonzero(late) + start).tolist():
                if i < skip_until:
                    continue
                run = _late_run(rows.t, i, int(before[i - start]) - self.window_ns)
                if run >= STEP_MIN_SAMPLES:
                    stop = step_at = i
                    break
                if i + run == len(rows) and not final:  # undecided: wait for the next batch
                    self._held = rows.take(np.arange(i, len(rows)))
                    keep[i:] = False
                    stop = i
                    break
                self._drop_late(rows, np.arange(i, i + run), path)
                keep[i : i + run] = False
                skip_until = i + run
            n = stop - start
            ooo = np.flatnonzero((seg[:n] < before[:n]) & ~late[:n])
            if ooo.size:
                self._strict(path, int(rows.offsets[start + int(ooo[0])]), "re-sorted")
                self.counts.reordered += int(ooo.size)
            if n:
                self._max_t = max(int(before[n - 1]), int(seg[n - 1]))
            if step_at is None:
                break
            if self._is_copy(rows, step_at):
                self._start_copy(rows, step_at, path)
                start = self._drop_copy(rows, step_at, keep)
                continue
            self._step(rows, step_at, path)
            start = step_at
        if not keep.any():
            return None
        return rows.take(np.flatnonzero(keep)) if not keep.all() else rows

    def _is_copy(self, rows: Rows, i: int) -> bool:
        """Whether the rows from ``i`` repeat rows of the stream's start exactly."""
        at = np.flatnonzero(self._head.t == int(rows.t[i]) - self._shift)
        if not at.size:
            return False
        j = int(at[0])
        n = min(COPY_MATCH_ROWS, len(self._head) - j, len(rows) - i)
        if n < min(STEP_MIN_SAMPLES, len(self._head)) or not n:
            return False
        if j + n > self._first_index + i:  # the rows matched must all precede the copy
            return False
        if not np.array_equal(rows.t[i : i + n] - self._shift, self._head.t[j : j + n]):
            return False
        for name, col in self._head.columns.items():
            other = rows.columns.get(name)
            if name == "t_ns" or other is None:
                continue
            a, b = other[i : i + n], col[j : j + n]
            same = a == b
            if a.dtype.kind == "f":
                same |= np.isnan(a) & np.isnan(b)
            if not bool(np.all(same)):
                return False
        return True

    def _start_copy(self, rows: Rows, i: int, path: Path) -> None:
        assert self._max_t is not None
        offset = int(rows.offsets[i])
        if self.strict:
            raise CorruptLogError(
                f"stream {self.name}: a duplicated copy of the log starts here (time goes back "
                f"to the start and the rows repeat it exactly)",
                path=path,
                offset=offset,
                hint="--strict refuses it; without it the copy is dropped and reported",
            )
        self._copy_until = self._max_t
        self.counts.copies.append(DuplicateCopy(offset, int(rows.t[i]) - self._shift, str(path)))

    def _drop_copy(self, rows: Rows, start: int, keep: Bools) -> int:
        """Inside a duplicated copy: drop the rows from ``start`` that do not go past the end
        of the original; returns the first row after the copy (``len(rows)`` if none)."""
        if self._copy_until is None or start >= len(rows):
            return start
        beyond = np.flatnonzero(rows.t[start:] > self._copy_until)
        end = start + int(beyond[0]) if beyond.size else len(rows)
        keep[start:end] = False
        self.counts.copies[-1].rows_dropped += end - start
        if beyond.size:
            self._copy_until = None
        return end

    def _step(self, rows: Rows, i: int, path: Path) -> None:
        assert self._max_t is not None
        t_at = int(rows.t[i])
        nominal = self._nominal_ns or 1
        shift = self._max_t + nominal - t_at
        if self.strict:
            raise CorruptLogError(
                f"stream {self.name}: time goes backwards by {(self._max_t - t_at) * 1e-9:.3f} s",
                path=path,
                offset=int(rows.offsets[i]),
                hint="--strict refuses clock steps; without it the stream is split and the "
                "later segment re-based",
            )
        rows.columns["t_ns"] = np.concatenate([rows.t[:i], rows.t[i:] + shift])
        self._shift += shift
        self.counts.steps.append(
            TimeStep(
                int(rows.offsets[i]),
                t_at - self._shift + shift,
                t_at - self._max_t,
                shift,
                str(path),
            )
        )

    def _drop_late(self, rows: Rows, idx: I64, path: Path) -> None:
        self._strict(path, int(rows.offsets[idx[0]]), "older than the reorder window")
        self.counts.dropped_late += len(idx)
        room = _MAX_LISTED - len(self.counts.dropped_late_offsets)
        self.counts.dropped_late_offsets.extend(rows.offsets[idx[:room]].tolist())

    # -------------------------------------------------------------------------------- emission
    def _emit(self, accepted: Rows | None, path: Path, *, final: bool) -> Rows:
        parts = [self._pending] + ([accepted] if accepted is not None else [])
        pool = Rows.concat(parts)
        if not len(pool):
            return pool
        if self.secondary is None:
            order = np.argsort(pool.t, kind="stable")
        else:
            order = np.lexsort((pool.columns[self.secondary], pool.t))
        pool = pool.take(order)
        pool = self._dedupe(pool, path)
        if final or self._max_t is None:
            cut = len(pool)
        else:
            cut = int(np.searchsorted(pool.t, self._max_t - self.window_ns, side="left"))
        out = pool.take(np.arange(cut))
        self._pending = pool.take(np.arange(cut, len(pool)))
        self.counts.rows_out += len(out)
        return out

    def _dedupe(self, pool: Rows, path: Path) -> Rows:
        t = pool.t
        equal = t[1:] == t[:-1]
        if self.secondary is not None:
            key = pool.columns[self.secondary]
            equal &= key[1:] == key[:-1]
        same = np.flatnonzero(equal) + 1
        if not same.size:
            return pool
        starts = np.ones(len(t), bool)
        starts[same] = False
        group_first = np.maximum.accumulate(np.where(starts, np.arange(len(t)), 0))
        rows = same
        firsts = group_first[rows]
        exact = np.ones(len(rows), bool)
        for col in pool.columns.values():
            a, b = col[rows], col[firsts]
            eq = a == b
            if col.dtype.kind == "f":
                eq |= np.isnan(a) & np.isnan(b)
            exact &= eq
        for mask in pool.nulls.values():
            exact &= mask[rows] == mask[firsts]
        conflicting = rows[~exact]
        self.counts.duplicates_exact += int(exact.sum())
        if conflicting.size:
            self._strict(path, int(pool.offsets[conflicting[0]]), "duplicate time, other values")
            self.counts.duplicates_conflicting += int(conflicting.size)
            room = _MAX_LISTED - len(self.counts.duplicates_conflicting_offsets)
            self.counts.duplicates_conflicting_offsets.extend(
                pool.offsets[conflicting[:room]].tolist()
            )
        keep = np.ones(len(t), bool)
        keep[rows] = False
        return pool.take(np.flatnonzero(keep))

    def _strict(self, path: Path, offset: int, what: str) -> None:
        if self.strict:
            raise CorruptLogError(
                f"stream {self.name}: a sample {what}",
                path=path,
                offset=int(offset),
                hint="--strict refuses reordered, late or conflicting samples",
            )

    @staticmethod
    def _empty_like(rows: Rows) -> Rows:
        return rows.take(np.arange(0))


def _late_run(t: I64, i: int, threshold: int) -> int:
    """Length of the run from ``i`` of samples below ``threshold`` that do not decrease,
    counted up to ``STEP_MIN_SAMPLES`` (all that the step decision needs)."""
    end = min(len(t), i + STEP_MIN_SAMPLES)
    j = i + 1
    while j < end and t[j] < threshold and t[j] >= t[j - 1]:
        j += 1
    return j - i


def _median_dt(t: I64) -> int | None:
    dt = np.diff(np.sort(t))
    dt = dt[dt > 0]
    return int(np.median(dt)) if dt.size else None
