"""Single-point positioning inside ingest: receiver position and clock per epoch, vectorized.

Ingest needs a receiver position for two things, and neither is the navigation solution
(that is ``pipeline``'s business): the satellite states of ``gnss_obs`` are taken at the
signal's transmit time and rotated into the receive-time ECEF frame, which needs the
receiver's place and clock (``ingest.gnss.obsgeometry``); and the cross-stream time check compares
the receiver's fixes with positions solved from the observations (``ingest.gnss.fixcheck``).

The model is that of ``gnss_obs``: ``rho_corr = |s - r| + b`` with ``rho_corr = pseudorange_m
+ sat_clock_m - iono_delay_m - tropo_delay_m`` (``ingest.schema``). All epochs are solved at
once by Gauss-Newton on stacked 4x4 normal equations (rows sorted by epoch), so the cost is a
few numpy passes over the rows, not a Python loop over epochs.

Models used only for positioning here (never written into a table): a standard tropospheric
delay (``tropo_delay_m``: 2.3 m zenith at sea level scaled by ``exp(-h / 7 km)``, mapped by
``1 / sin(el)``), good to a few decimetres above 15 deg; and the broadcast Klobuchar
ionospheric model (``klobuchar_delay_m``, IS-GPS-200 20.3.3.5.2.5), which ingest does write,
because its coefficients are broadcast data carried by the navigation file.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import numpy.typing as npt

from navreplay.ingest.gnss.ephemeris import C_MPS

F64 = npt.NDArray[np.float64]
I64 = npt.NDArray[np.int64]
B = npt.NDArray[np.bool_]

_MIN_SATS = 4
_MAX_COND = 1e12
_OUTLIER_M = 30.0
_OUTLIER_MADS = 6.0


class EpochFix(NamedTuple):
    """Per-epoch receiver solution.

    Attributes:
        ecef_m: receiver ECEF position, m, shape (E, 3) (NaN where unsolved).
        clock_m: receiver clock bias times c, m, shape (E,).
        solved: the epoch had >= 4 usable rows and converged, shape (E,).
        rms_m: RMS of the post-fit residuals of the rows used, m, shape (E,).
        used: the rows that took part (outliers rejected), shape (n,).
    """

    ecef_m: F64
    clock_m: F64
    solved: B
    rms_m: F64
    used: B


def epoch_index(t_ns: I64) -> tuple[I64, I64]:
    """(epoch index per row, start row per epoch) of rows sorted by ``t_ns``."""
    t = np.asarray(t_ns, dtype=np.int64)
    if t.size == 0:
        return np.empty(0, np.int64), np.empty(0, np.int64)
    new = np.concatenate(([True], t[1:] != t[:-1]))
    return np.cumsum(new) - 1, np.flatnonzero(new)


def solve(
    sat_m: F64,
    pr_corr_m: F64,
    epoch: I64,
    n_epochs: int,
    *,
    x0: F64 | None = None,
    weight: F64 | None = None,
    max_iter: int = 12,
    tol_m: float = 1e-4,
    reject_outliers: bool = True,
) -> EpochFix:
    """Least-squares position and clock of every epoch.

    Args:
        sat_m: satellite ECEF positions in the receive-time frame, m, shape (n, 3).
        pr_corr_m: corrected pseudoranges (see the module docstring), m, shape (n,).
        epoch: epoch index of each row, non-decreasing, shape (n,).
        n_epochs: number of epochs E (epochs without rows stay unsolved).
        x0: initial [x, y, z, clock] per epoch, shape (E, 4); the earth's centre if None.
        weight: inverse variances per row; equal weights if None.
        max_iter: Gauss-Newton iterations at most.
        tol_m: stop when every epoch's update is shorter than this.
        reject_outliers: after convergence, drop the worst row of an epoch whose residual
            exceeds ``max(30 m, 6 x 1.4826 MAD)`` (epochs with >= 6 rows) and solve again.
    """
    n = pr_corr_m.shape[0]
    used = np.isfinite(pr_corr_m) & np.isfinite(sat_m).all(axis=1)
    w = np.ones(n) if weight is None else np.asarray(weight, dtype=np.float64)
    x = np.zeros((n_epochs, 4)) if x0 is None else np.array(x0, dtype=np.float64)
    x[~np.isfinite(x).all(axis=1)] = 0.0
    x, ok, res = _gauss_newton(sat_m, pr_corr_m, epoch, n_epochs, x, w, used, max_iter, tol_m)
    if reject_outliers:
        bad = _worst_outliers(res, epoch, n_epochs, used)
        if bad.size:
            used[bad] = False
            x, ok, res = _gauss_newton(
                sat_m, pr_corr_m, epoch, n_epochs, x, w, used, max_iter, tol_m
            )
    sq = np.where(used, res * res, 0.0)
    counts = np.bincount(epoch[used], minlength=n_epochs)
    rms = np.sqrt(np.bincount(epoch, sq, minlength=n_epochs) / np.maximum(counts, 1))
    pos = np.where(ok[:, None], x[:, :3], np.nan)
    return EpochFix(pos, np.where(ok, x[:, 3], np.nan), ok, np.where(ok, rms, np.nan), used)


def _gauss_newton(
    sat: F64,
    pr: F64,
    epoch: I64,
    n_ep: int,
    x: F64,
    w: F64,
    used: B,
    max_iter: int,
    tol_m: float,
) -> tuple[F64, B, F64]:
    counts = np.bincount(epoch[used], minlength=n_ep)
    ok = counts >= _MIN_SATS
    wu = np.where(used, w, 0.0)
    res = np.full(pr.shape, np.nan)
    for _ in range(max_iter):
        d = sat - x[epoch, :3]
        rng = np.linalg.norm(d, axis=1)
        h = np.empty((pr.shape[0], 4))
        h[:, :3] = -d / rng[:, None]
        h[:, 3] = 1.0
        res = np.where(used, pr - rng - x[epoch, 3], 0.0)
        hw = h * wu[:, None]
        normal = np.zeros((n_ep, 4, 4))
        rhs = np.zeros((n_ep, 4))
        np.add.at(normal, epoch, hw[:, :, None] * h[:, None, :])
        np.add.at(rhs, epoch, hw * res[:, None])
        good = ok & (np.linalg.cond(normal) < _MAX_COND)
        step = np.zeros((n_ep, 4))
        if good.any():
            step[good] = np.linalg.solve(normal[good], rhs[good][..., None])[..., 0]
        ok = good
        x = x + step
        if not good.any() or np.max(np.linalg.norm(step[good, :3], axis=1)) < tol_m:
            break
    d = sat - x[epoch, :3]
    res = pr - np.linalg.norm(d, axis=1) - x[epoch, 3]
    return x, ok, res


def _worst_outliers(res: F64, epoch: I64, n_ep: int, used: B) -> I64:
    """Per epoch with >= 6 used rows, the worst row if it is an outlier."""
    out: list[int] = []
    counts = np.bincount(epoch[used], minlength=n_ep)
    for e in np.flatnonzero(counts >= 6).tolist():
        rows = np.flatnonzero((epoch == e) & used)
        r = res[rows]
        dev = np.abs(r - np.median(r))
        mad = 1.4826 * float(np.median(dev))
        k = int(np.argmax(dev))
        if dev[k] > max(_OUTLIER_M, _OUTLIER_MADS * mad):
            out.append(int(rows[k]))
    return np.asarray(out, dtype=np.int64)


def tropo_delay_m(elevation_rad: F64, height_m: F64) -> F64:
    """Standard tropospheric delay: 2.3 m zenith at sea level, ``exp(-h / 7 km)``, ``1/sin
    el`` mapping (elevation floored at 3 deg)."""
    el = np.maximum(np.asarray(elevation_rad, dtype=np.float64), math.radians(3.0))
    h = np.clip(np.asarray(height_m, dtype=np.float64), -500.0, 9000.0)
    return np.asarray(2.3 * np.exp(-h / 7000.0) / np.sin(el), dtype=np.float64)


def klobuchar_delay_m(
    lat_rad: F64,
    lon_rad: F64,
    elevation_rad: F64,
    azimuth_rad: F64,
    gps_tow_s: F64,
    alpha: tuple[float, float, float, float],
    beta: tuple[float, float, float, float],
) -> F64:
    """GPS L1 ionospheric delay of the broadcast Klobuchar model, m (IS-GPS-200 20.3.3.5.2.5).

    Angles in radians (converted to semicircles inside), ``gps_tow_s`` the GPS time of week
    in seconds; ``alpha``/``beta`` the broadcast coefficients (s, s/sc, s/sc^2, s/sc^3 and s,
    s/sc ...). Arrays broadcast.
    """
    el_sc = np.asarray(elevation_rad, dtype=np.float64) / math.pi
    psi = 0.0137 / (el_sc + 0.11) - 0.022
    phi = np.clip(np.asarray(lat_rad) / math.pi + psi * np.cos(azimuth_rad), -0.416, 0.416)
    lam = np.asarray(lon_rad) / math.pi + psi * np.sin(azimuth_rad) / np.cos(phi * math.pi)
    phi_m = phi + 0.064 * np.cos((lam - 1.617) * math.pi)
    t = np.mod(43200.0 * lam + np.asarray(gps_tow_s, dtype=np.float64), 86400.0)
    amp = np.maximum(sum(a * phi_m**k for k, a in enumerate(alpha)), 0.0)
    per = np.maximum(sum(b * phi_m**k for k, b in enumerate(beta)), 72000.0)
    x = 2.0 * math.pi * (t - 50400.0) / per
    f = 1.0 + 16.0 * (0.53 - el_sc) ** 3
    day = 5e-9 + amp * (1.0 - x * x / 2.0 + x**4 / 24.0)
    delay_s = f * np.where(np.abs(x) < 1.57, day, 5e-9)
    return np.asarray(C_MPS * delay_s, dtype=np.float64)
