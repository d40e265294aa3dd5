"""Outage windows and their metrics, for a run of any family.

``Window`` is one window as the run's metadata records it; where windows lie in a log is the
scenarios' business (``scenarios.windows``). ``ErrorTrack`` is a run's position error against
its reference by time: from any family's ``estimate.parquet`` (``table_track``) or from an
INS run's full state (``ins.tracks``). ``window_metrics`` measures a track over the
windows, as ``WindowMetricsParams`` (the ``scenarios.metrics`` section) defines:

The error at every instant of a window is the estimate's position error against the
reference, exactly as the filter had it: nothing is subtracted at the window's start (a
re-aligned segment hides the error the filter already had, the FusionCore pitfall of
``docs/peers.md``). The reference is the truth when the dataset has one; on a real log
without truth it is the GNSS fixes the scenario withheld (and those outside the windows, for
the re-convergence), compared with the estimate moved to the antenna by the lever arm.

Per window ``[start, end)``: the error at the start (the common state the filter entered the
outage with) and at the end (the last estimate before the first epoch back; also split into
its components along and across the direction of travel, and down), its maximum,
mean and RMS, the distance travelled (along the reference), the drift as a percentage of that
distance, the fraction of the window the error stays inside 3 sigma on every axis, and the
re-convergence time: the time after ``end`` until the 3-D error falls below
``max(reconverge_floor_m, reconverge_factor * RMS over pre_window_s before the window)`` and
stays there for ``reconverge_hold_s``, searched until the next window (None if never).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pyarrow as pa

from navreplay.ingest.typed import FieldError
from navreplay.pipeline.nav.earth import E2, F64, I64, A

NS = 1_000_000_000


@dataclass(frozen=True)
class Window:
    """One window of a scenario, as written into the run's metadata.

    Attributes:
        start_ns, end_ns: ``[start, end)`` on the log's time base, ns.
        kind: ``outage`` (no GNSS), ``partial`` (``sats`` satellites kept), or the fault
            kind (``F1`` ...) for fault windows.
        sats: satellites available inside (0 for outages; None for faults that keep them).
        label: human-readable description.
    """

    start_ns: int
    end_ns: int
    kind: str
    sats: int | None
    label: str

    @property
    def duration_s(self) -> float:
        return (self.end_ns - self.start_ns) / NS

    def contains(self, t_ns: I64) -> np.ndarray:
        """Boolean mask of the times inside the window."""
        return np.asarray((t_ns >= self.start_ns) & (t_ns < self.end_ns))

    def to_json(self, t0_ns: int) -> dict[str, object]:
        """The window for metrics.json: absolute ns and seconds from ``t0_ns``."""
        return {
            "kind": self.kind,
            "label": self.label,
            "start_t_ns": self.start_ns,
            "end_t_ns": self.end_ns,
            "start_s": (self.start_ns - t0_ns) / NS,
            "duration_s": self.duration_s,
            "sats": self.sats,
        }


@dataclass(frozen=True)
class WindowMetricsParams:
    """Definitions of the outage-window metrics (``estimation.ins.tracks``).

    Attributes:
        reconverge_factor: re-converged once the 3-D error is below this factor times its
            RMS over the ``pre_window_s`` before the window ...
        reconverge_floor_m: ... or below this, whichever is larger, m ...
        reconverge_hold_s: ... and stays there this long, s.
        pre_window_s: the span before a window that sets the error level to return to, s.
        min_distance_m: drift as a percentage of distance is undefined below this, m.
    """

    reconverge_factor: float = 2.0
    reconverge_floor_m: float = 1.0
    reconverge_hold_s: float = 5.0
    pre_window_s: float = 30.0
    min_distance_m: float = 50.0

    def __post_init__(self) -> None:
        if self.reconverge_factor < 1:
            raise FieldError("reconverge_factor", "must be >= 1")
        if min(self.reconverge_floor_m, self.reconverge_hold_s, self.pre_window_s) <= 0:
            raise FieldError("reconverge_floor_m", "floor, hold and pre-window must be > 0")


@dataclass(frozen=True)
class ErrorTrack:
    """Position errors of a run against its reference, by time.

    Attributes:
        t_ns: (K,) times; err_ned_m: (K, 3) reference minus estimate, NED metres;
        sigma_ned_m: (K, 3) the filter's 1-sigma (NaN where unknown);
        ref_ned_m: (K, 3) the reference positions in the local NED frame at ``origin``
            (for distances and the direction of travel);
        reference: ``truth`` or ``withheld_fixes``;
        origin: (lat rad, lon rad, h m) of that frame;
        axes: 3, or 2 for a planar estimate (no height: the errors and the consistency are
            horizontal, the down column is zero and not used).
    """

    t_ns: I64
    err_ned_m: F64
    sigma_ned_m: F64
    ref_ned_m: F64
    reference: str
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)
    axes: int = 3


Origin = tuple[float, float, float]


def local_ned(lat: F64, lon: F64, h: F64, origin: Origin | None) -> tuple[F64, Origin]:
    """Geodetic (rad, rad, m) to metres north/east/down of ``origin`` (default: the first
    point; small extents), and the origin used."""
    if lat.size == 0:
        return np.zeros((0, 3)), origin or (0.0, 0.0, 0.0)
    lat0, lon0, h0 = origin or (float(lat[0]), float(lon[0]), float(h[0]))
    if not math.isfinite(h0):  # a reference without height: its down component stays NaN
        h0 = 0.0
    s2 = math.sin(lat0) ** 2
    rn = A / math.sqrt(1.0 - E2 * s2)
    rm = rn * (1.0 - E2) / (1.0 - E2 * s2)
    ned = np.column_stack(
        [
            (lat - lat0) * (rm + h0),
            np.angle(np.exp(1j * (lon - lon0))) * (rn + h0) * math.cos(lat0),
            -(h - h0),
        ]
    )
    return ned, (lat0, lon0, h0)


def _rms(a: F64) -> float | None:
    return float(np.sqrt(np.mean(np.square(a)))) if a.size else None


def reconverge_s(
    t_ns: I64, err_m: F64, end_ns: int, until_ns: int, threshold_m: float, hold_s: float
) -> float | None:
    """Seconds after ``end_ns`` until ``err_m`` stays below the threshold for ``hold_s``.

    Searched over the samples in ``[end_ns, until_ns)``; None when the error never settles for
    the whole hold within them.
    """
    sel = (t_ns >= end_ns) & (t_ns < until_ns)
    t, e = t_ns[sel], err_m[sel]
    if t.size == 0:
        return None
    bad = np.concatenate([[0], np.cumsum(e > threshold_m)])
    hold = round(hold_s * NS)
    j = np.searchsorted(t, t + hold, side="right")
    settled = (bad[j] - bad[np.arange(t.size)] == 0) & (t + hold <= t[-1])
    if not settled.any():
        return None
    return float((t[int(np.argmax(settled))] - end_ns) / NS)


def _along_cross_down(err_ned: F64, ref_ned: F64) -> tuple[float | None, ...]:
    """|error| at the last sample along the direction of travel, across it, and down.

    The direction is that of the reference over the window's last 10 % (horizontal); None
    when the reference does not move.
    """
    if err_ned.shape[0] < 2:
        return (None, None, None)
    k = max(1, err_ned.shape[0] // 10)
    d = ref_ned[-1, :2] - ref_ned[-1 - k, :2]
    norm = float(np.hypot(d[0], d[1]))
    if norm < 1e-3:
        return (None, None, abs(float(err_ned[-1, 2])))
    u = d / norm
    e = err_ned[-1]
    along = float(e[0] * u[0] + e[1] * u[1])
    cross = float(-e[0] * u[1] + e[1] * u[0])
    return (abs(along), abs(cross), abs(float(e[2])))


def window_metrics(
    track: ErrorTrack,
    windows: Sequence[Window],
    t0_ns: int,
    params: WindowMetricsParams,
) -> list[dict[str, Any]]:
    """The metrics of every window (see the module docstring); JSON-ready dicts."""
    n = track.axes
    err3 = np.sqrt(np.sum(track.err_ned_m[:, :n] ** 2, axis=1))
    t = track.t_ns
    out = []
    starts = sorted(w.start_ns for w in windows)
    for w in windows:
        inside = w.contains(t)
        e = err3[inside]
        later = [s for s in starts if s >= w.end_ns]
        until = later[0] if later else int(t[-1]) + 1 if t.size else w.end_ns
        pre = (t >= w.start_ns - round(params.pre_window_s * NS)) & (t < w.start_ns)
        level = _rms(err3[pre])
        thr = max(params.reconverge_floor_m, params.reconverge_factor * (level or 0.0))
        ref = track.ref_ned_m[inside]
        dist = (
            float(np.sum(np.linalg.norm(np.diff(ref[:, :n], axis=0), axis=1)))
            if e.size > 1
            else 0.0
        )
        sig = track.sigma_ned_m[inside]
        within = np.all(np.abs(track.err_ned_m[inside][:, :n]) <= 3.0 * sig[:, :n], axis=1)
        end = float(e[-1]) if e.size else None
        along = _along_cross_down(track.err_ned_m[inside], ref)
        if n < 3:
            along = (*along[:2], None)
        row: dict[str, Any] = {
            "kind": w.kind,
            "start_s": (w.start_ns - t0_ns) / NS,
            "start_t_ns": w.start_ns,
            "duration_s": w.duration_s,
            "sats": w.sats,
            "samples": int(e.size),
            "reference": track.reference,
            "err_start_m": float(e[0]) if e.size else None,
            "err_end_m": end,
            "err_max_m": float(e.max()) if e.size else None,
            "err_mean_m": float(e.mean()) if e.size else None,
            "err_rms_m": _rms(e),
            "err_h_end_m": float(np.hypot(*track.err_ned_m[inside][-1, :2])) if e.size else None,
            "err_end_along_m": along[0],
            "err_end_cross_m": along[1],
            "err_end_down_m": along[2],
            "sigma_end_m": float(np.linalg.norm(sig[-1, :n])) if e.size else None,
            "inside_3sigma_frac": float(within.mean()) if e.size else None,
            "distance_m": dist,
            "drift_pct_distance": (
                100.0 * end / dist if end is not None and dist >= params.min_distance_m else None
            ),
            "pre_window_rms_m": level,
            "reconverge_threshold_m": thr,
            "reconverge_s": reconverge_s(t, err3, w.end_ns, until, thr, params.reconverge_hold_s),
        }
        out.append(row)
    return out


def ned_error(lat: F64, lon: F64, h: F64, ref_lat: F64, ref_lon: F64, ref_h: F64) -> F64:
    """(K, 3) reference minus estimate in metres north, east, down at the estimate's
    (``lat``, ``lon`` rad, ``h`` m); small offsets."""
    s2 = np.sin(lat) ** 2
    rn = A / np.sqrt(1.0 - E2 * s2)
    rm = rn * (1.0 - E2) / (1.0 - E2 * s2)
    return np.column_stack(
        [
            (ref_lat - lat) * (rm + h),
            np.angle(np.exp(1j * (ref_lon - lon))) * (rn + h) * np.cos(lat),
            -(ref_h - h),
        ]
    )


def _geodetic(table: pa.Table, t_ns: I64 | None = None) -> tuple[I64, F64, F64, F64]:
    """(t, lat rad, lon rad, h m) of a table's finite positions (interpolated to ``t_ns``
    inside its span when given)."""
    t = np.asarray(table.column("t_ns").to_numpy(), dtype=np.int64)
    lat, lon, h = (
        np.asarray(table.column(c).to_numpy(zero_copy_only=False), dtype=np.float64)
        for c in ("lat_deg", "lon_deg", "alt_m")
    )
    ok = np.isfinite(lat) & np.isfinite(lon) & np.isfinite(h)
    t, lat, lon, h = t[ok], np.radians(lat[ok]), np.radians(lon[ok]), h[ok]
    if t_ns is None or t.size == 0:
        return t, lat, lon, h
    tq = t_ns[(t_ns >= t[0]) & (t_ns <= t[-1])]
    tf, tqf = t.astype(np.float64), tq.astype(np.float64)
    return tq, np.interp(tqf, tf, lat), np.interp(tqf, tf, np.unwrap(lon)), np.interp(tqf, tf, h)


def table_track(
    estimate: pa.Table, truth: pa.Table | None, fixes: pa.Table | None
) -> ErrorTrack | None:
    """A run's errors read from its ``estimate.parquet`` (any family): against the truth at
    the estimate's times, else against the fixes at theirs (the estimate interpolated; no
    lever arm: a family without attitude estimates the point its fixes give). A planar
    estimate (no ``alt_sigma_m`` column, or one without a value) gives a 2-axis track."""
    if estimate.num_rows == 0:
        return None
    planar = (
        "alt_sigma_m" not in estimate.column_names
        or estimate.column("alt_sigma_m").null_count == estimate.num_rows
    )
    if truth is not None and truth.num_rows:
        t, lat, lon, h = _geodetic(truth, _geodetic(estimate)[0])
        e_t, e_lat, e_lon, e_h = _geodetic(estimate, t)
        reference = "truth"
    elif fixes is not None and fixes.num_rows:
        e_t0 = _geodetic(estimate)[0]
        t, lat, lon, h = _geodetic(fixes)
        keep = (t >= e_t0[0]) & (t <= e_t0[-1]) if e_t0.size else np.zeros(t.size, bool)
        t, lat, lon, h = t[keep], lat[keep], lon[keep], h[keep]
        e_t, e_lat, e_lon, e_h = _geodetic(estimate, t)
        reference = "withheld_fixes"
    else:
        return None
    if t.size == 0 or e_t.size != t.size:
        return None
    err = ned_error(e_lat, e_lon, e_h, lat, lon, h)
    if planar:
        err[:, 2] = 0.0
    t_est = np.asarray(estimate.column("t_ns").to_numpy(), dtype=np.int64)
    near = np.clip(np.searchsorted(t_est, t), 0, t_est.size - 1)
    sig = np.column_stack(
        [
            np.asarray(estimate.column(c).to_numpy(zero_copy_only=False), dtype=np.float64)[near]
            if c in estimate.column_names
            else np.full(t.size, np.nan)
            for c in ("lat_sigma_m", "lon_sigma_m", "alt_sigma_m")
        ]
    )
    ref, org = local_ned(lat, lon, h, None)
    return ErrorTrack(t, err, sig, ref, reference, org, axes=2 if planar else 3)
