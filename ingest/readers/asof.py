"""Nearest-time join of two streams read block by block, in bounded memory.

Autopilot logs split one logical sample over several messages (DataFlash ``GPS`` and its
accuracies in ``GPA``; MAVLink ``GLOBAL_POSITION_INT`` and the attitude in ``ATTITUDE``),
logged together but as separate records. ``AsofJoin`` gives each row of the left stream the
right stream's columns from the sample nearest in time, when one lies within ``tolerance_ns``;
otherwise they are null ("not provided"). A left row is released once the right stream has
advanced past its time plus the tolerance (or at the end), so only the rows waiting for a
partner and about a second of right rows are held.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from navreplay.ingest.arrays import I64

Columns = dict[str, np.ndarray]
Nulls = dict[str, npt.NDArray[np.bool_]]

_KEEP_NS = 1_000_000_000


@dataclass
class Left:
    """Rows of the left stream: time, columns, null masks and record offsets."""

    t: I64
    columns: Columns
    nulls: Nulls
    offsets: I64

    def __len__(self) -> int:
        return len(self.t)

    def take(self, idx: npt.NDArray[np.intp] | slice) -> Left:
        return Left(
            self.t[idx],
            {k: v[idx] for k, v in self.columns.items()},
            {k: v[idx] for k, v in self.nulls.items()},
            self.offsets[idx],
        )


@dataclass
class AsofJoin:
    """Join ``names`` columns of a right stream onto a left stream (see the module docstring).

    Attributes:
        matched: left rows that got a partner; ``unmatched``: those that did not.
    """

    names: tuple[str, ...]
    tolerance_ns: int
    matched: int = 0
    unmatched: int = 0
    _left: list[Left] = field(default_factory=list)
    _rt: I64 = field(default_factory=lambda: np.empty(0, np.int64))
    _rcols: Columns = field(default_factory=dict)
    _frontier: int | None = None

    def push_left(self, rows: Left) -> None:
        if len(rows):
            self._left.append(rows)

    def push_right(self, t: I64, columns: Columns) -> None:
        if not len(t):
            return
        rt = np.concatenate([self._rt, t])
        order = np.argsort(rt, kind="stable")
        self._rt = rt[order]
        for name in self.names:
            old = self._rcols.get(name, np.empty(0, np.float64))
            self._rcols[name] = np.concatenate([old, columns[name]])[order]

    def pop(self, *, final: bool = False) -> Left | None:
        """The left rows whose partner is settled, joined; None when there are none."""
        if not self._left:
            return None
        rows = _concat(self._left)
        self._left = []
        watermark = int(self._rt[-1]) if len(self._rt) else None
        if final:
            ready = np.ones(len(rows), bool)
        elif watermark is None:
            ready = np.zeros(len(rows), bool)
        else:
            ready = rows.t + self.tolerance_ns <= watermark
        if not ready.all():
            self._left.append(rows.take(np.flatnonzero(~ready)))
        if not ready.any():
            return None
        out = rows.take(np.flatnonzero(ready))
        self._join(out)
        self._trim(int(out.t.max()))
        return out

    def _join(self, out: Left) -> None:
        n = len(out)
        if len(self._rt):
            j = np.clip(np.searchsorted(self._rt, out.t), 1, max(len(self._rt) - 1, 1))
            lo = np.maximum(j - 1, 0)
            hi = np.minimum(j, len(self._rt) - 1)
            pick = np.where(np.abs(self._rt[lo] - out.t) <= np.abs(self._rt[hi] - out.t), lo, hi)
            ok = np.abs(self._rt[pick] - out.t) <= self.tolerance_ns
        else:
            pick = np.zeros(n, np.intp)
            ok = np.zeros(n, bool)
        for name in self.names:
            values = self._rcols[name][pick] if len(self._rt) else np.zeros(n)
            out.columns[name] = np.where(ok, values, 0.0)  # null where not ok
            out.nulls[name] = ~ok
        self.matched += int(ok.sum())
        self.unmatched += int((~ok).sum())

    def _trim(self, released_max: int) -> None:
        self._frontier = max(self._frontier or released_max, released_max)
        pending = [int(p.t.min()) for p in self._left]
        keep_from = min([self._frontier, *pending]) - self.tolerance_ns - _KEEP_NS
        cut = int(np.searchsorted(self._rt, keep_from))
        if cut:
            self._rt = self._rt[cut:]
            self._rcols = {k: v[cut:] for k, v in self._rcols.items()}


def through(chain: list[AsofJoin], *, final: bool = False) -> Left | None:
    """The left rows that have passed every join of ``chain`` in turn (each hands on the
    rows it has settled to the next); None when none has passed them all yet."""
    out = chain[0].pop(final=final)
    for join in chain[1:]:
        if out is not None:
            join.push_left(out)
        out = join.pop(final=final)
    return out


def _concat(parts: list[Left]) -> Left:
    if len(parts) == 1:
        return parts[0]
    null_names = sorted({k for p in parts for k in p.nulls})
    return Left(
        np.concatenate([p.t for p in parts]),
        {k: np.concatenate([p.columns[k] for p in parts]) for k in parts[0].columns},
        {
            k: np.concatenate([p.nulls.get(k, np.zeros(len(p), bool)) for p in parts])
            for k in null_names
        },
        np.concatenate([p.offsets for p in parts]),
    )
