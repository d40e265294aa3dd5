"""Time alignment between the streams of one dataset, from the speed each one implies.

Streams recorded on different clocks and put on one time base can still be offset: a UTC/GPS
mix-up (18 s of leap seconds), a receiver's output latency, a wrong boot-clock pairing
(catalogue case 36, filter fault F20). Every table that implies a horizontal speed gives a
speed signal:

- ``vehicle``: ``speed_mps`` (wheel or radar speed);
- ``gnss``, ``truth``, ``estimator``: the norm of ``vel_n_mps``/``vel_e_mps`` where given,
  else the speed from differencing consecutive positions (WGS-84 radii of curvature).

For each pair, both signals are resampled on a common grid over their overlap (no value
across a gap longer than ``GAP_FACTOR`` median periods), de-meaned, and cross-correlated by
FFT; the lag of the peak is refined by a parabola through its neighbours. ``lag_s > 0`` means
the second stream's stamps are late: ``b(t) = a(t - lag_s)``. A lag beyond ``WARN_LAG_S`` with
a clear peak (correlation at least ``MIN_CORRELATION``) is a warning in the ingest report.

The onboard estimator runs on the vehicle's clock, the IMU's, and fuses its GNSS with the
receiver's delay compensated: where its speed and the fixes' correlate clearly, the fixes'
lag behind it is the latency the replayed filters must allow for (``fix_latency``; ArduPilot
assumes 220 ms for a u-blox, PX4 110 ms), which a log's clock pairing keeps when it maps the
vehicle clock onto the fixes' arrivals.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import numpy.typing as npt
import pyarrow.parquet as pq

from navreplay.ingest.arrays import F64, I64

SPEED_TABLES = ("gnss", "vehicle", "truth", "estimator")
MAX_LAG_S = 30.0
WARN_LAG_S = 0.3
MIN_CORRELATION = 0.7
MIN_SPEED_STD_MPS = 0.3
LATENCY_MIN_CORRELATION = 0.9  # a fix latency is taken from a clear peak only ...
LATENCY_MIN_OVERLAP_S = 30.0  # ... over this much common signal ...
LATENCY_RANGE_S = (0.02, 1.0)  # ... within a receiver's delays (beyond: a clock problem)
GAP_FACTOR = 5.0
_GRID_S = 0.01
_MAX_GRID = 1 << 20
_A_M = 6_378_137.0  # WGS-84
_E2 = 6.694379990141317e-3


@dataclass(frozen=True)
class Alignment:
    """The estimated offset between two streams' speed signals.

    Attributes:
        a, b: the tables compared.
        lag_s: b's stamps are late by this much (b(t) = a(t - lag_s)).
        correlation: normalised correlation at the peak (1 = identical shapes).
        overlap_s: length of the common time span used.
        speed_ratio: median of b/a where both move (> 1 m/s): a scale-factor check.
        sources: how each speed was obtained.
    """

    a: str
    b: str
    lag_s: float
    correlation: float
    overlap_s: float
    speed_ratio: float | None
    sources: tuple[str, str]

    @property
    def suspicious(self) -> bool:
        return abs(self.lag_s) > WARN_LAG_S and self.correlation >= MIN_CORRELATION

    def to_json(self) -> dict[str, Any]:
        return {
            "streams": [self.a, self.b],
            "signal": f"horizontal speed ({self.sources[0]} vs {self.sources[1]})",
            "lag_s": round(self.lag_s, 4),
            "correlation": round(self.correlation, 4),
            "overlap_s": round(self.overlap_s, 2),
            "speed_ratio": None if self.speed_ratio is None else round(self.speed_ratio, 4),
        }

    def text(self) -> str:
        return (
            f"{self.b} vs {self.a}: {self.b} lags by {self.lag_s:+.3f} s "
            f"(speed correlation {self.correlation:.3f} over {self.overlap_s:.0f} s)"
        )


def speed_signal(columns: dict[str, np.ndarray], table: str) -> tuple[I64, F64, str] | None:
    """(t_ns, speed m/s, source) of a table's columns, or None if it implies no speed."""
    t = np.asarray(columns["t_ns"], dtype=np.int64)
    if table == "vehicle":
        v = columns.get("speed_mps")
        return None if v is None else (t, np.abs(np.asarray(v, np.float64)), "speed_mps")
    vn, ve = columns.get("vel_n_mps"), columns.get("vel_e_mps")
    if vn is not None and ve is not None and np.isfinite(vn).mean() > 0.5:
        return t, np.hypot(np.asarray(vn, np.float64), np.asarray(ve, np.float64)), "velocity"
    lat, lon = columns.get("lat_deg"), columns.get("lon_deg")
    if lat is None or lon is None or len(t) < 3:
        return None
    lat_r = np.radians(np.asarray(lat, np.float64))
    lon_r = np.radians(np.asarray(lon, np.float64))
    mid_lat = 0.5 * (lat_r[1:] + lat_r[:-1])
    w2 = 1.0 - _E2 * np.sin(mid_lat) ** 2
    north = np.diff(lat_r) * _A_M * (1.0 - _E2) / w2**1.5  # meridian radius
    east = np.diff(lon_r) * _A_M / np.sqrt(w2) * np.cos(mid_lat)  # prime-vertical radius
    dt = np.diff(t) * 1e-9
    step = np.hypot(north, east) / np.where(dt > 0, dt, np.nan)
    mid = t[:-1] + np.diff(t) // 2
    return mid, step, "position differences"


def estimate_lag(
    t_a: I64, v_a: F64, t_b: I64, v_b: F64, *, max_lag_s: float = MAX_LAG_S
) -> tuple[float, float, float] | None:
    """(lag_s, correlation, overlap_s) of b against a, or None without enough common signal."""
    ok_a, ok_b = np.isfinite(v_a), np.isfinite(v_b)
    t_a, v_a, t_b, v_b = t_a[ok_a], v_a[ok_a], t_b[ok_b], v_b[ok_b]
    if len(t_a) < 10 or len(t_b) < 10:
        return None
    start, stop = max(t_a[0], t_b[0]), min(t_a[-1], t_b[-1])
    overlap = (stop - start) * 1e-9
    if overlap <= 4 * _GRID_S:
        return None
    step = max(_GRID_S, overlap / _MAX_GRID)
    grid = start + np.arange(0.0, overlap, step) * 1e9
    a, ma = _resample(t_a, v_a, grid)
    b, mb = _resample(t_b, v_b, grid)
    if a[ma].std() < MIN_SPEED_STD_MPS or b[mb].std() < MIN_SPEED_STD_MPS:
        return None
    a, b = np.where(ma, a - a[ma].mean(), 0.0), np.where(mb, b - b[mb].mean(), 0.0)
    k = min(int(max_lag_s / step), len(grid) // 3)
    pearson = _lagged_pearson(a, ma.astype(np.float64), b, mb.astype(np.float64), k)
    if not np.isfinite(pearson).any():
        return None
    i = int(np.nanargmax(pearson))
    frac = 0.0
    if 0 < i < len(pearson) - 1 and np.isfinite(pearson[i - 1 : i + 2]).all():
        y0, y1, y2 = pearson[i - 1], pearson[i], pearson[i + 1]
        den = y0 - 2 * y1 + y2
        frac = 0.5 * (y0 - y2) / den if den != 0 else 0.0
    return float((i - k + frac) * step), float(pearson[i]), float(overlap)


def _lagged_pearson(a: F64, ma: F64, b: F64, mb: F64, k: int) -> F64:
    """Pearson correlation of ``a[n]`` with ``b[n + s]`` over the samples valid in both, for
    shifts s = -k..k (every sum is one FFT cross-correlation, so the cost is O(n log n))."""
    size = 1 << math.ceil(math.log2(2 * len(a)))
    spectra: dict[int, np.ndarray] = {}

    def xcorr(x: F64, y: F64) -> F64:
        fx = spectra.setdefault(id(x), np.fft.rfft(x, size))
        fy = spectra.setdefault(id(y), np.fft.rfft(y, size))
        full = np.fft.irfft(fy * np.conj(fx), size)
        return np.concatenate([full[size - k :], full[: k + 1]])

    a2, b2 = a * a, b * b
    n = xcorr(ma, mb)
    sa, sb = xcorr(a, mb), xcorr(ma, b)
    saa, sbb, sab = xcorr(a2, mb), xcorr(ma, b2), xcorr(a, b)
    with np.errstate(invalid="ignore", divide="ignore"):
        cov = sab - sa * sb / n
        var = (saa - sa * sa / n) * (sbb - sb * sb / n)
        out = cov / np.sqrt(var)
    out[(n < 0.5 * n.max()) | (var <= 0)] = np.nan
    return np.asarray(out, dtype=np.float64)


def _resample(t: I64, v: F64, grid: F64) -> tuple[F64, npt.NDArray[np.bool_]]:
    """Linear interpolation on ``grid`` and a mask of points not inside a gap."""
    x = (t - t[0]).astype(np.float64)
    g = grid - t[0]
    out = np.interp(g, x, v)
    dt = np.diff(x)
    median = float(np.median(dt[dt > 0])) if (dt > 0).any() else 1.0
    j = np.clip(np.searchsorted(x, g), 1, len(x) - 1)
    inside = (x[j] - x[j - 1]) <= GAP_FACTOR * median
    return out, inside & (g >= x[0]) & (g <= x[-1])


def check_tables(directory: Path, tables: list[str]) -> list[Alignment]:
    """Pairwise alignment of the speed signals of ``tables`` written in ``directory``."""
    signals: dict[str, tuple[I64, F64, str]] = {}
    for name in tables:
        if name not in SPEED_TABLES:
            continue
        path = directory / f"{name}.parquet"
        wanted = ["t_ns", "speed_mps", "vel_n_mps", "vel_e_mps", "lat_deg", "lon_deg"]
        present = [c for c in wanted if c in pq.read_schema(path).names]
        table = pq.read_table(path, columns=present)
        cols = {c: table.column(c).to_numpy(zero_copy_only=False) for c in present}
        cols = {c: np.asarray(v, np.float64) if c != "t_ns" else v for c, v in cols.items()}
        sig = speed_signal(cols, name)
        if sig is not None:
            signals[name] = sig
    out: list[Alignment] = []
    names = [n for n in SPEED_TABLES if n in signals]
    for i, a in enumerate(names):
        for b in names[i + 1 :]:
            ta, va, sa = signals[a]
            tb, vb, sb = signals[b]
            est = estimate_lag(ta, va, tb, vb)
            if est is None:
                continue
            lag, corr, overlap = est
            out.append(Alignment(a, b, lag, corr, overlap, _ratio(ta, va, tb, vb, lag), (sa, sb)))
    return out


def fix_latency(aligned: list[Alignment]) -> tuple[float, str] | None:
    """(latency s, how it was measured) of the GNSS fixes against the onboard estimator, or
    None where the log has no clear, plausible lag between them (see the module docstring)."""
    for a in aligned:
        if (a.a, a.b) != ("gnss", "estimator"):
            continue
        latency = -a.lag_s  # b(t) = a(t - lag): the fixes are late by -lag
        lo, hi = LATENCY_RANGE_S
        clear = a.correlation >= LATENCY_MIN_CORRELATION and a.overlap_s >= LATENCY_MIN_OVERLAP_S
        if clear and lo <= latency <= hi:
            return latency, (
                f"the fixes lag the onboard estimator by {latency:.3f} s (speed correlation "
                f"{a.correlation:.3f} over {a.overlap_s:.0f} s)"
            )
    return None


def _ratio(t_a: I64, v_a: F64, t_b: I64, v_b: F64, lag_s: float) -> float | None:
    ok = np.isfinite(v_a)
    t_a, v_a = t_a[ok], v_a[ok]
    shifted = np.interp(t_b - lag_s * 1e9, t_a, v_a, left=np.nan, right=np.nan)
    moving = (shifted > 1.0) & (v_b > 1.0)
    return float(np.median(v_b[moving] / shifted[moving])) if moving.sum() >= 10 else None
