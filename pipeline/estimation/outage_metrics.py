"""Outage-window metrics (architecture section 5): drift measured against a reference with no
re-alignment.

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

from navreplay.pipeline.estimation.models import ins
from navreplay.pipeline.estimation.replay import RunResult
from navreplay.pipeline.estimation.truth import error_states, truth_at
from navreplay.pipeline.estimation.windows import NS, Window, WindowMetricsParams
from navreplay.pipeline.nav.earth import E2, F64, I64, A
from navreplay.pipeline.nav.rotations import quat_to_dcm


@dataclass(frozen=True)
class ErrorTrack:
    """Position errors of a run against its reference, by time.

    Attributes:
        t_ns: (K,) times; err_ned_m: (K, 3) reference minus estimate, NED metres;
        sigma_ned_m: (K, 3) the filter's 1-sigma (NaN where unknown);
        ref_ned_m: (K, 3) the reference positions in the local NED frame at ``origin``
            (for distances and the direction of travel);
        reference: ``truth`` or ``withheld_fixes``;
        origin: (lat rad, lon rad, h m) of that frame.
    """

    t_ns: I64
    err_ned_m: F64
    sigma_ned_m: F64
    ref_ned_m: F64
    reference: str
    origin: tuple[float, float, float] = (0.0, 0.0, 0.0)


Origin = tuple[float, float, float]


def _local_ned(lat: F64, lon: F64, h: F64, origin: Origin | None) -> tuple[F64, Origin]:
    """Geodetic (rad, rad, m) to metres north/east/down of ``origin`` (default: the first
    point; small extents), and the origin used."""
    if lat.size == 0:
        return np.zeros((0, 3)), origin or (0.0, 0.0, 0.0)
    lat0, lon0, h0 = origin or (float(lat[0]), float(lon[0]), float(h[0]))
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


def truth_track(result: RunResult, truth: pa.Table, origin: Origin | None = None) -> ErrorTrack:
    """Errors against the truth table at the estimate's times (``truth.error_states``);
    reference positions relative to ``origin`` (default: the first)."""
    inside, err, _ = error_states(result, truth)
    t = result.t_ns[inside]
    _, tr = truth_at(truth, t)
    sig = np.sqrt(np.clip(np.diagonal(result.P[inside], axis1=1, axis2=2)[:, :3], 0.0, None))
    ref, org = _local_ned(np.radians(tr["lat_deg"]), np.radians(tr["lon_deg"]), tr["alt_m"], origin)
    return ErrorTrack(t, err[:, :3], sig, ref, "truth", org)


def fixes_track(
    result: RunResult, fixes: pa.Table, lever_b: Sequence[float], origin: Origin | None = None
) -> ErrorTrack:
    """Errors against GNSS fixes (antenna positions) at the fix times inside the run.

    The estimate is interpolated linearly to each fix time and moved to the antenna by the
    lever arm (body FRD, rotated by the estimated attitude).
    """
    t_fix = np.asarray(fixes.column("t_ns").to_numpy(), dtype=np.int64)
    cols = {}
    for name in ("lat_deg", "lon_deg", "alt_m"):
        c = fixes.column(name)
        cols[name] = np.asarray(c.to_numpy(zero_copy_only=False), dtype=np.float64)
    ok = np.isfinite(cols["lat_deg"]) & np.isfinite(cols["lon_deg"]) & np.isfinite(cols["alt_m"])
    if result.t_ns.size:
        ok &= (t_fix >= result.t_ns[0]) & (t_fix <= result.t_ns[-1])
    else:
        ok[:] = False
    t = t_fix[ok]
    te, x = result.t_ns.astype(np.float64), result.x
    lat = np.interp(t, te, x[:, ins.X_LAT])
    lon = np.interp(t, te, np.unwrap(x[:, ins.X_LON]))
    h = np.interp(t, te, x[:, ins.X_H])
    near = np.clip(np.searchsorted(result.t_ns, t), 0, max(result.t_ns.size - 1, 0))
    lever = np.asarray(lever_b, dtype=np.float64)
    arm = np.array([quat_to_dcm(x[j, ins.X_Q : ins.X_Q + 4]) @ lever for j in near]).reshape(-1, 3)
    s2 = np.sin(lat) ** 2
    rn = A / np.sqrt(1.0 - E2 * s2)
    rm = rn * (1.0 - E2) / (1.0 - E2 * s2)
    f_lat, f_lon = np.radians(cols["lat_deg"][ok]), np.radians(cols["lon_deg"][ok])
    err = np.column_stack(
        [
            (f_lat - lat) * (rm + h) - arm[:, 0],
            np.angle(np.exp(1j * (f_lon - lon))) * (rn + h) * np.cos(lat) - arm[:, 1],
            -(cols["alt_m"][ok] - h) - arm[:, 2],
        ]
    )
    P = result.P[near] if result.P.size else np.zeros((0, 3, 3))
    sig = np.sqrt(np.clip(np.diagonal(P, axis1=1, axis2=2)[:, :3], 0.0, None))
    ref, org = _local_ned(f_lat, f_lon, cols["alt_m"][ok], origin)
    return ErrorTrack(t, err, sig, ref, "withheld_fixes", org)


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
    err3 = np.sqrt(np.sum(track.err_ned_m**2, axis=1))
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
        dist = float(np.sum(np.linalg.norm(np.diff(ref, axis=0), axis=1))) if e.size > 1 else 0.0
        sig = track.sigma_ned_m[inside]
        within = np.all(np.abs(track.err_ned_m[inside]) <= 3.0 * sig, axis=1)
        end = float(e[-1]) if e.size else None
        along = _along_cross_down(track.err_ned_m[inside], ref)
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
            "sigma_end_m": float(np.linalg.norm(sig[-1])) if e.size else None,
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


def outage_windows(
    result: RunResult,
    truth: pa.Table | None,
    fixes: pa.Table | None,
    lever_b: Sequence[float],
    windows: Sequence[Window],
    t0_ns: int,
    params: WindowMetricsParams,
) -> list[dict[str, Any]]:
    """Window metrics against the truth, else against the (withheld) fixes; [] without any."""
    if not windows or result.t_ns.size == 0:
        return []
    if truth is not None and truth.num_rows:
        track = truth_track(result, truth)
    elif fixes is not None and fixes.num_rows:
        track = fixes_track(result, fixes, lever_b)
    else:
        return []
    return window_metrics(track, windows, t0_ns, params)
