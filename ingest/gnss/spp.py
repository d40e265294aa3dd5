"""Single-point positioning: receiver position and clock (and velocity and drift) by
iterative weighted least squares on pseudoranges and their rates. The one SPP solver of the
project: ingest places the receiver for the satellite states of ``gnss_obs``
(``ingest.gnss.obsgeometry``, ``ingest.gnss.gsdc``) and for the check of fixes against
observations (``ingest.gnss.fixcheck``); ``pipeline`` solves the k-satellite fixes of its
scenarios and the initial alignment of its filters with it.

Inputs follow the ``gnss_obs`` conventions (``ingest.schema``): satellite positions and
velocities at transmit time in the ECEF frame of the receive time (Sagnac applied), and
pseudoranges corrected by the satellite clock, ``rho_corr = pseudorange_m + sat_clock_m -
iono_delay_m - tropo_delay_m``. The measurement model is ``rho_i = |s_i - r| + b`` and
``rhodot_i = e_i . (v_s,i - v_r) + d`` with ``e_i`` the unit vector from receiver to satellite
(paper 001, eq. 7-8 without the lever arm).

``solve_position`` (Gauss-Newton on one epoch, numba-compiled) is the solver; ``solve`` runs it
over every epoch of a table (rows sorted by epoch) in one compiled loop, with an optional
rejection of one outlier per epoch.

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
from numba import njit

from navreplay.ingest.arrays import F64, I64, Bools
from navreplay.ingest.gnss.ephemeris import C_MPS

STATE_DIM = 4
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
    solved: Bools
    rms_m: F64
    used: Bools


def epoch_index(t_ns: I64) -> tuple[I64, I64]:
    """(epoch index per row, start row per epoch) of rows sorted by ``t_ns``."""
    t = np.asarray(t_ns, dtype=np.int64)
    if t.size == 0:
        return np.empty(0, np.int64), np.empty(0, np.int64)
    new = np.concatenate(([True], t[1:] != t[:-1]))
    return np.cumsum(new) - 1, np.flatnonzero(new)


def epoch_starts(t_ns: I64) -> I64:
    """Row ranges of the epochs of rows sorted by ``t_ns``: epoch k holds rows
    ``starts[k]:starts[k + 1]`` (one more element than there are epochs)."""
    _, first = epoch_index(t_ns)
    return np.append(first, np.int64(np.size(t_ns))).astype(np.int64)


@njit(cache=True)
def solve_position(
    sat_pos: F64, pr_corr: F64, weight: F64, x0: F64, max_iter: int, tol_m: float
) -> tuple[F64, F64, int, bool]:
    """Receiver ECEF position and clock bias from >= 4 corrected pseudoranges.

    Args:
        sat_pos: satellite ECEF positions, m, shape (n, 3).
        pr_corr: satellite-clock-corrected pseudoranges, m, shape (n,).
        weight: inverse variances, 1/m^2, shape (n,).
        x0: initial [x, y, z, clock_bias] in m (the earth's centre works), shape (4,).
        max_iter: Gauss-Newton iterations at most.
        tol_m: stop when the update is shorter than this.

    Returns:
        (x, covariance (4, 4) = (H^T W H)^-1, iterations, converged). With fewer than four
        satellites or a singular geometry, x is NaN and converged is False.
    """
    n = sat_pos.shape[0]
    x = x0.copy()
    cov = np.full((STATE_DIM, STATE_DIM), np.nan)
    if n < STATE_DIM:
        return np.full(STATE_DIM, np.nan), cov, 0, False
    H = np.empty((n, STATE_DIM))
    y = np.empty(n)
    for it in range(1, max_iter + 1):
        for i in range(n):
            dx = sat_pos[i, 0] - x[0]
            dy = sat_pos[i, 1] - x[1]
            dz = sat_pos[i, 2] - x[2]
            rng = math.sqrt(dx * dx + dy * dy + dz * dz)
            H[i, 0], H[i, 1], H[i, 2], H[i, 3] = -dx / rng, -dy / rng, -dz / rng, 1.0
            y[i] = pr_corr[i] - rng - x[3]
        HtW = H.T * weight
        N = HtW @ H
        if abs(np.linalg.det(N)) < 1e-12:
            return np.full(STATE_DIM, np.nan), cov, it, False
        cov = np.linalg.inv(N).astype(np.float64)
        step = cov @ (HtW @ y)
        x += step
        if math.sqrt(step[0] ** 2 + step[1] ** 2 + step[2] ** 2) < tol_m:
            return x, cov, it, True
    return x, cov, max_iter, False


@njit(cache=True)
def solve_velocity(
    sat_pos: F64, sat_vel: F64, rate_corr: F64, weight: F64, rx_pos: F64
) -> tuple[F64, F64]:
    """Receiver ECEF velocity and clock drift from >= 4 corrected pseudorange rates.

    ``rate_corr`` is ``pseudorange_rate_mps + sat_clock_drift_mps`` (m/s); ``rx_pos`` the
    receiver ECEF position. Returns ([vx, vy, vz, drift] in m/s, covariance (4, 4)); NaN
    when under-determined.
    """
    n = sat_pos.shape[0]
    if n < STATE_DIM:
        return np.full(STATE_DIM, np.nan), np.full((STATE_DIM, STATE_DIM), np.nan)
    H = np.empty((n, STATE_DIM))
    y = np.empty(n)
    for i in range(n):
        d = sat_pos[i] - rx_pos
        e = d / math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
        H[i, 0], H[i, 1], H[i, 2], H[i, 3] = -e[0], -e[1], -e[2], 1.0
        y[i] = rate_corr[i] - (e[0] * sat_vel[i, 0] + e[1] * sat_vel[i, 1] + e[2] * sat_vel[i, 2])
    HtW = H.T * weight
    N = HtW @ H
    if abs(np.linalg.det(N)) < 1e-12:
        return np.full(STATE_DIM, np.nan), np.full((STATE_DIM, STATE_DIM), np.nan)
    cov = np.linalg.inv(N).astype(np.float64)
    return cov @ (HtW @ y), cov


@njit(cache=True)
def dop_enu(sat_pos: F64, rx_pos: F64, c_en: F64) -> F64:
    """Unit-weight covariance diagonal [east, north, up, clock] of the geometry (DOP^2 each).

    ``c_en`` is the rotation taking ECEF vectors to NED at the receiver. HDOP = sqrt(q_e +
    q_n), VDOP = sqrt(q_u), PDOP = sqrt(q_e + q_n + q_u). NaN with fewer than four satellites.
    """
    n = sat_pos.shape[0]
    if n < STATE_DIM:
        return np.full(STATE_DIM, np.nan)
    H = np.empty((n, STATE_DIM))
    for i in range(n):
        d = sat_pos[i] - rx_pos
        los = c_en @ (d / math.sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]))
        H[i, 0], H[i, 1], H[i, 2], H[i, 3] = -los[1], -los[0], los[2], 1.0
    N = H.T @ H
    if abs(np.linalg.det(N)) < 1e-12:
        return np.full(STATE_DIM, np.nan)
    Q = np.linalg.inv(N)
    return np.array([Q[0, 0], Q[1, 1], Q[2, 2], Q[3, 3]])


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
    """``solve_position`` for every epoch of a table.

    Args:
        sat_m: satellite ECEF positions in the receive-time frame, m, shape (n, 3).
        pr_corr_m: corrected pseudoranges (see the module docstring), m, shape (n,).
        epoch: epoch index of each row, non-decreasing, shape (n,).
        n_epochs: number of epochs E (epochs without rows stay unsolved).
        x0: initial [x, y, z, clock] per epoch, shape (E, 4); the earth's centre if None
            (and for every epoch whose row is not finite).
        weight: inverse variances per row; equal weights if None.
        max_iter: Gauss-Newton iterations at most, per epoch.
        tol_m: an epoch has converged when its update is shorter than this.
        reject_outliers: after convergence, drop the worst row of an epoch whose residual
            exceeds ``max(30 m, 6 x 1.4826 MAD)`` (epochs with >= 6 rows) and solve again.
    """
    n = pr_corr_m.shape[0]
    used = np.isfinite(pr_corr_m) & np.isfinite(sat_m).all(axis=1)
    w = np.ones(n) if weight is None else np.asarray(weight, dtype=np.float64)
    x = np.zeros((n_epochs, 4)) if x0 is None else np.array(x0, dtype=np.float64)
    x[~np.isfinite(x).all(axis=1)] = 0.0
    starts = np.searchsorted(epoch, np.arange(n_epochs + 1)).astype(np.int64)
    sat = np.ascontiguousarray(sat_m, dtype=np.float64)
    pr = np.ascontiguousarray(pr_corr_m, dtype=np.float64)
    x, ok = _solve_each(starts, sat, pr, w, used, x, max_iter, tol_m)
    res = _residuals(sat, pr, epoch, x)
    if reject_outliers:
        bad = _worst_outliers(res, epoch, n_epochs, used)
        if bad.size:
            used[bad] = False
            x, ok = _solve_each(starts, sat, pr, w, used, x, max_iter, tol_m)
            res = _residuals(sat, pr, epoch, x)
    sq = np.where(used, res * res, 0.0)
    counts = np.bincount(epoch[used], minlength=n_epochs)
    rms = np.sqrt(np.bincount(epoch, sq, minlength=n_epochs) / np.maximum(counts, 1))
    pos = np.where(ok[:, None], x[:, :3], np.nan)
    return EpochFix(pos, np.where(ok, x[:, 3], np.nan), ok, np.where(ok, rms, np.nan), used)


@njit(cache=True)
def _solve_each(
    starts: I64, sat: F64, pr: F64, w: F64, used: Bools, x0: F64, max_iter: int, tol_m: float
) -> tuple[F64, Bools]:
    """``solve_position`` on the used rows ``starts[k]:starts[k + 1]`` of every epoch k from
    ``x0[k]``; an epoch that does not converge keeps ``x0[k]``."""
    n_ep = starts.shape[0] - 1
    x = x0.copy()
    ok = np.zeros(n_ep, dtype=np.bool_)
    for k in range(n_ep):
        rows = starts[k] + np.flatnonzero(used[starts[k] : starts[k + 1]])
        if rows.size < STATE_DIM:
            continue
        xk, _, _, conv = solve_position(sat[rows], pr[rows], w[rows], x0[k], max_iter, tol_m)
        if conv:
            x[k] = xk
            ok[k] = True
    return x, ok


def _residuals(sat: F64, pr: F64, epoch: I64, x: F64) -> F64:
    """Post-fit residual of every row, m."""
    return np.asarray(
        pr - np.linalg.norm(sat - x[epoch, :3], axis=1) - x[epoch, 3], dtype=np.float64
    )


def _worst_outliers(res: F64, epoch: I64, n_ep: int, used: Bools) -> I64:
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
