"""A companion stream: columns recorded on another topic, joined to a table's rows by time.

A ROS GNSS driver publishes the receiver's fix (``NavSatFix``) and its velocity
(``TwistWithCovarianceStamped``) as two topics stamped with the same epoch; the canonical
``gnss`` table holds both in one row. ``Companion`` cleans the velocity stream like any
stream (``StreamCleaner``), buffers it, and ``join`` gives each fix the velocity stamped
within ``TOLERANCE_NS`` of it; fixes without one get nulls ("not provided"), velocities without
a fix are counted and dropped. Memory: the buffer holds the velocities not yet joined, at
most one output block's worth.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from navreplay.ingest.hygiene import Rows, StreamCleaner

TOLERANCE_NS = 5_000_000


class Companion:
    """The buffered, cleaned companion stream of one table.

    Args:
        key: the companion stream's key.
        columns: the columns it contributes (besides ``t_ns``).
        window_ns, strict: as for ``StreamCleaner``.
    """

    def __init__(self, key: str, columns: tuple[str, ...], window_ns: int, *, strict: bool) -> None:
        self.key = key
        self.columns = columns
        self.cleaner = StreamCleaner(key, window_ns, strict=strict)
        self._rows: list[Rows] = []
        self.watermark: int | None = None
        self.matched = 0
        self.unmatched_rows = 0
        self.dropped = 0

    def push(self, rows: Rows, path: Path) -> None:
        self._keep(self.cleaner.push(rows, path))

    def finish(self, path: Path) -> None:
        self._keep(self.cleaner.finish(path))
        self.watermark = None if not self._rows else int(self._rows[-1].t[-1])

    def _keep(self, rows: Rows) -> None:
        if len(rows):
            self._rows.append(rows)
            self.watermark = int(rows.t[-1])

    def join(self, rows: Rows, *, final: bool = False) -> None:
        """Add the companion columns to ``rows`` (sorted), in place, consuming the buffer;
        with ``final``, companion rows after the last row are counted as dropped."""
        pool = Rows.concat(self._rows)
        n = len(rows)
        if len(pool):
            upto = int(np.searchsorted(pool.t, int(rows.t[-1]) + TOLERANCE_NS, side="right"))
            here, rest = pool.take(np.arange(upto)), pool.take(np.arange(upto, len(pool)))
        else:
            here, rest = pool, pool
        self._rows = [rest] if len(rest) and not final else []
        if final:
            self.dropped += len(rest)
        idx, ok = _nearest(here.t if len(here) else np.empty(0, np.int64), rows.t)
        used = np.unique(idx[ok])
        self.matched += int(ok.sum())
        self.unmatched_rows += int(n - ok.sum())
        self.dropped += len(here) - len(used)
        for name in self.columns:
            values: Any = np.full(n, np.nan)
            null = ~ok
            if len(here) and name in here.columns:
                values[ok] = here.columns[name][idx[ok]]
                if name in here.nulls:
                    null = null | (ok & here.nulls[name][np.where(ok, idx, 0)])
            rows.columns[name] = values
            rows.nulls[name] = null

    def discard_rest(self) -> None:
        """Count companion rows left without a row (the table ended first) as dropped."""
        self.dropped += sum(len(r) for r in self._rows)
        self._rows = []

    def report(self) -> dict[str, Any]:
        return {
            "stream": self.key,
            "hygiene": self.cleaner.counts.to_json(),
            "joined": self.matched,
            "rows_without_companion": self.unmatched_rows,
            "companion_rows_without_row_dropped": self.dropped,
            "tolerance_ms": TOLERANCE_NS * 1e-6,
        }


def _nearest(ref: np.ndarray, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Index into sorted ``ref`` of the nearest time to each ``t``, and whether it is close."""
    if not len(ref):
        return np.zeros(len(t), np.int64), np.zeros(len(t), bool)
    hi = np.clip(np.searchsorted(ref, t), 0, len(ref) - 1)
    lo = np.clip(hi - 1, 0, len(ref) - 1)
    pick = np.where(np.abs(ref[lo] - t) <= np.abs(ref[hi] - t), lo, hi)
    return pick, np.abs(ref[pick] - t) <= TOLERANCE_NS
