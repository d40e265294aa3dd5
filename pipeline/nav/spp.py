"""Single-point positioning: iterative weighted least squares on pseudoranges and their rates.

Inputs follow the ``gnss_obs`` conventions (``ingest.schema``): satellite positions and
velocities at transmit time in the ECEF frame of the receive time (Sagnac applied), and
pseudoranges corrected by the satellite clock (``pseudorange_m + sat_clock_m - iono - tropo``).
The measurement model is ``rho_i = |s_i - r| + b`` and
``rhodot_i = e_i . (v_s,i - v_r) + d`` with ``e_i`` the unit vector from receiver to
satellite (paper 001, eq. 7-8 without the lever arm). Everything is numba-compiled; the
``*_epochs`` functions solve many epochs given as contiguous row ranges.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from navreplay.pipeline._jit import njit
from navreplay.pipeline.nav.earth import F64, I64, dcm_ecef_to_ned, ecef_to_geodetic

STATE_DIM = 4


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
def dop_enu(sat_pos: F64, rx_pos: F64) -> F64:
    """Unit-weight covariance diagonal [east, north, up, clock] of the geometry (DOP^2 each).

    HDOP = sqrt(q_e + q_n), VDOP = sqrt(q_u), PDOP = sqrt(q_e + q_n + q_u). NaN with fewer
    than four satellites.
    """
    n = sat_pos.shape[0]
    if n < STATE_DIM:
        return np.full(STATE_DIM, np.nan)
    lat, lon, _ = ecef_to_geodetic(rx_pos[0], rx_pos[1], rx_pos[2])
    c_en = dcm_ecef_to_ned(lat, lon)
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


@njit(cache=True)
def solve_epochs(
    starts: I64, sat_pos: F64, pr_corr: F64, weight: F64, max_iter: int, tol_m: float
) -> tuple[F64, npt.NDArray[np.bool_]]:
    """``solve_position`` for every epoch; epoch k holds rows ``starts[k]:starts[k+1]``.

    ``starts`` has one more element than there are epochs (the last is the row count). Each
    epoch starts from the previous solution (the earth's centre for the first). Returns
    (x per epoch (E, 4), converged (E,)).
    """
    n_ep = starts.shape[0] - 1
    out = np.full((n_ep, STATE_DIM), np.nan)
    ok = np.zeros(n_ep, dtype=np.bool_)
    x0 = np.zeros(STATE_DIM)
    for k in range(n_ep):
        a, b = starts[k], starts[k + 1]
        x, _, _, conv = solve_position(sat_pos[a:b], pr_corr[a:b], weight[a:b], x0, max_iter, tol_m)
        out[k] = x
        ok[k] = conv
        if conv:
            x0 = x.copy()
    return out, ok


def epoch_starts(t_ns: I64) -> I64:
    """Row ranges of the epochs of a table sorted by ``t_ns`` (for the ``*_epochs`` solvers)."""
    t = np.asarray(t_ns, dtype=np.int64)
    if t.size == 0:
        return np.zeros(1, dtype=np.int64)
    change = np.flatnonzero(np.diff(t)) + 1
    return np.concatenate(([0], change, [t.size])).astype(np.int64)
