"""Per-stream audit statistics, accumulated block by block in bounded memory.

``StreamAudit.observe`` sees every block a stream writes (after hygiene, so sorted and
unique) and keeps: the row count, first/last time, a bounded deterministic sample of the
sample intervals (for rate, median dt and jitter), every interval that could be a gap, and
NaN/inf counts per column. It also turns +-inf into NaN in place: invalid stays NaN, never
null (catalogue case 21).

``StreamAudit.report(gap_factor)`` gives the stream's section of ``ingest_report.json``:

- ``rate_hz`` = 1 / median dt; ``jitter_ms`` = 1.4826 * median |dt - median dt| (MAD, robust
  to gaps); ``max_dt_ms``;
- ``gaps``: intervals longer than ``gap_factor`` x median dt (case 33), with count, total,
  longest and the first ones listed;
- ``segments``: gaps longer than ``max(60 s, 1000 x median dt)`` are listed again as segment
  boundaries (a forward clock jump or a recording paused: case 32); filters restart there;
- ``nonfinite``: per column, NaN and inf counts (inf already converted to NaN);
- ``implausible``: per column, values beyond what any vehicle or sensor produces
  (``LIMITS``: |specific force| > 2000 m/s^2, |rate| > 100 rad/s, |lat| > 90 deg ...): in a
  format without checksums (ULog, DataFlash, CSV) the trace bit damage leaves. They are
  counted, not changed.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt

#: |value| above which a column's value is physically implausible (counted, not changed)
LIMITS: dict[str, float] = {
    **{f"acc_{a}_mps2": 2000.0 for a in "xyz"},
    **{f"gyro_{a}_radps": 100.0 for a in "xyz"},
    **{f"vel_{a}_mps": 1000.0 for a in "ned"},
    **{f"mag_{a}_gauss": 100.0 for a in "xyz"},
    "lat_deg": 90.0,
    "lon_deg": 180.0,
    "alt_m": 100_000.0,
}
_RESERVOIR = 1 << 18
_MAX_CANDIDATES = 100_000
_MAX_LISTED = 10
SEGMENT_MIN_S = 60.0
SEGMENT_MIN_PERIODS = 1000


@dataclass
class _Candidate:
    t_ns: int
    dt_ns: int
    offset: int


@dataclass
class StreamAudit:
    """Statistics of one stream (see the module docstring)."""

    rows: int = 0
    first_t_ns: int | None = None
    last_t_ns: int | None = None
    nonfinite: dict[str, dict[str, int]] = field(default_factory=dict)
    implausible: dict[str, int] = field(default_factory=dict)
    _dts: npt.NDArray[np.int64] = field(default_factory=lambda: np.empty(0, np.int64))
    _stride: int = 1
    _phase: int = 0
    _candidates: list[_Candidate] = field(default_factory=list)
    _candidates_dropped: int = 0

    def observe(self, columns: dict[str, np.ndarray], offsets: npt.NDArray[np.int64]) -> None:
        """Account for a sorted block; converts +-inf to NaN in float columns, in place."""
        t = columns["t_ns"]
        if not len(t):
            return
        for name, col in columns.items():
            if col.dtype.kind != "f":
                continue
            nan = int(np.isnan(col).sum())
            inf = np.isinf(col)
            n_inf = int(inf.sum())
            if n_inf:
                col[inf] = np.nan
            if nan or n_inf:
                entry = self.nonfinite.setdefault(name, {"nan": 0, "inf": 0})
                entry["nan"] += nan
                entry["inf"] += n_inf
            limit = LIMITS.get(name)
            if limit is not None:
                over = int(np.count_nonzero(np.abs(col) > limit))
                if over:
                    self.implausible[name] = self.implausible.get(name, 0) + over
        full = t if self.last_t_ns is None else np.concatenate([[self.last_t_ns], t])
        offs = offsets if self.last_t_ns is None else np.concatenate([[offsets[0]], offsets])
        dt = np.diff(full)
        self._sample(dt)
        self._gap_candidates(full, dt, offs)
        if self.first_t_ns is None:
            self.first_t_ns = int(t[0])
        self.last_t_ns = int(t[-1])
        self.rows += len(t)

    def _sample(self, dt: npt.NDArray[np.int64]) -> None:
        picked = dt[self._phase :: self._stride]
        self._phase = (self._phase - len(dt)) % self._stride
        self._dts = np.concatenate([self._dts, picked])
        while len(self._dts) > _RESERVOIR:
            self._dts = self._dts[::2]
            self._stride *= 2
            self._phase = self._phase % self._stride

    def _gap_candidates(
        self,
        t: npt.NDArray[np.int64],
        dt: npt.NDArray[np.int64],
        offsets: npt.NDArray[np.int64],
    ) -> None:
        if len(self._dts) < 8:
            big = np.arange(len(dt))
        else:
            big = np.flatnonzero(dt > 1.5 * float(np.median(self._dts)))
        room = _MAX_CANDIDATES - len(self._candidates)
        self._candidates_dropped += max(0, len(big) - room)
        for i in big[: max(room, 0)].tolist():
            self._candidates.append(_Candidate(int(t[i]), int(dt[i]), int(offsets[i + 1])))

    def report(self, gap_factor: float) -> dict[str, Any]:
        out: dict[str, Any] = {
            "rows": self.rows,
            "first_t_ns": self.first_t_ns,
            "last_t_ns": self.last_t_ns,
            "duration_s": (
                (self.last_t_ns - self.first_t_ns) * 1e-9
                if self.first_t_ns is not None and self.last_t_ns is not None
                else None
            ),
            "nonfinite": self.nonfinite,
            "implausible": {
                k: {"count": n, "limit_abs": LIMITS[k]} for k, n in sorted(self.implausible.items())
            },
        }
        dts = self._dts[self._dts > 0]
        if not dts.size:
            out.update(rate_hz=None, median_dt_ms=None, jitter_ms=None, max_dt_ms=None)
            out["gaps"] = {"count": 0}
            out["segments"] = []
            return out
        med = float(np.median(dts))
        mad = float(np.median(np.abs(dts - med)))
        largest = max((c.dt_ns for c in self._candidates), default=int(dts.max()))
        out.update(
            rate_hz=1e9 / med,
            median_dt_ms=med * 1e-6,
            jitter_ms=1.4826 * mad * 1e-6,
            max_dt_ms=max(largest, int(dts.max())) * 1e-6,
        )
        threshold = gap_factor * med
        gaps = [c for c in self._candidates if c.dt_ns > threshold]
        listed = [
            {"after_t_ns": c.t_ns, "duration_s": c.dt_ns * 1e-9, "offset": c.offset}
            for c in gaps[:_MAX_LISTED]
        ]
        out["gaps"] = {
            "threshold_ms": threshold * 1e-6,
            "count": len(gaps),
            "total_s": sum(c.dt_ns for c in gaps) * 1e-9,
            "longest_s": max((c.dt_ns for c in gaps), default=0) * 1e-9,
            "first": listed,
            "uncounted_candidates": self._candidates_dropped,
        }
        seg_ns = max(SEGMENT_MIN_S * 1e9, SEGMENT_MIN_PERIODS * med)
        out["segments"] = [
            {"after_t_ns": c.t_ns, "jump_s": c.dt_ns * 1e-9, "offset": c.offset}
            for c in gaps
            if c.dt_ns > seg_ns
        ]
        return out
