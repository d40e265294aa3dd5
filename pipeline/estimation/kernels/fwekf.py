"""The fuzzy-adaptive weighted EKF of paper 004 (``fwekf``), compiled whole with numba.

The loosely coupled error-state EKF of ``kernels.ekf`` (same propagation, same measurement
front end ``ekf_prepare``, same Joseph update) with exponential data weighting (paper 004
eq. 21-27): at every stop that carries a GNSS fix the prior covariance is

    P- = alpha^2 Phi P Phi^T + Q                                             (eq. 26)

so the filter forgets old information at a rate set by ``alpha`` once per measurement cycle
(alpha = 1 is the plain EKF). After each fix's update, the normalized innovations
``nu / sqrt(S_ii)`` (prior covariance) of its position and velocity rows, accepted by the gate
or not (the paper's fuzzy system is what judges the residuals; a gate that hid the rejected
ones would blind it to exactly the faults it is meant to detect), enter a ring of the last
``window`` epochs; the fuzzy system (``estimation.fuzzy``: eq. 29-32, Table 1) turns the
ring's mean and covariance into the alpha of the next cycle.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from pipeline.estimation.fuzzy import FZ_WINDOW, infer_alpha, residual_inputs
from pipeline.estimation.kernels.common import (
    CFG_GAP_S,
    CFG_MAX_STEP,
    CFG_NHC_ON,
    CFG_SUBSTEPS,
    CNT_OUT,
    CNT_STOP,
    N_STREAMS,
    STATUS_INDEFINITE,
    STATUS_OK,
    check_state,
    fail,
    keep_pd,
    record_output,
)
from pipeline.estimation.kernels.ekf import ekf_prepare, joseph_update
from pipeline.estimation.models.ins import ACC_DIM, inject, propagate_span
from pipeline.estimation.models.ins_errors import transition
from pipeline.estimation.models.measurement import K_PR, ST_FIX, ST_OUT, ST_T, epoch_layout
from pipeline.nav.earth import F64, I64

RING_COLS = 6  # north, east, down position; north, east, down velocity


@nb.njit(cache=True)
def push_residuals(ring: F64, count: int, rows: I64, nu: F64, S: F64, m: int) -> int:
    """Append one epoch's normalized GNSS residuals (all rows, gated or not) to the ring;
    returns the new count."""
    slot = count % ring.shape[0]
    ring[slot, :] = math.nan
    for k in range(m):
        kind = rows[k, 0]
        if kind < K_PR:
            ring[slot, kind] = nu[k] / math.sqrt(S[k, k])
    return count + 1


@nb.njit(cache=True)
def run_fwekf(
    x0: F64, P0: F64, n: int, t0: int, i0: int, u0: F64, imu_t: I64, imu: F64, stops: I64,
    fix: F64, obs: F64, obs_start: I64, cfg: F64, noise: F64, lever_b: F64, nhc_sigma: F64,
    gate: F64, fz: F64, rules: I64, out_alpha: F64, m_max: int, out_t: I64, out_x: F64,
    out_P: F64, inn_i: I64, inn_f: F64, ev_i: I64, ev_f: F64, counts: I64,
) -> int:  # fmt: skip
    """Replay the FWEKF: ``kernels.ekf.run_ekf``'s arguments plus the fuzzy system.

    Args:
        fz: ``FuzzyParams.vector()``; rules: ``fuzzy.RULES``.
        out_alpha: out, the alpha in force at each output row.

    Returns:
        a ``common.STATUS_*`` code.
    """
    X = x0.copy()
    P = P0.copy()
    ones = np.ones(n)
    L = np.empty((n, n))
    Phi = np.empty((n, n))
    Qd = np.empty((n, n))
    work = np.zeros((9, 10))
    acc = np.zeros(ACC_DIM)
    u = u0.copy()
    u_end = np.empty(6)
    rows = np.empty((m_max, 2), np.int64)
    blocks = np.empty((m_max, 4), np.int64)
    z, r, nu = np.empty(m_max), np.empty(m_max), np.empty(m_max)
    H = np.empty((m_max, n))
    S = np.empty((m_max, m_max))
    acc_rows = np.empty(m_max, np.int64)
    reject_since = -np.ones(N_STREAMS, np.int64)
    ring = np.full((int(fz[FZ_WINDOW]), RING_COLS), math.nan)
    n_ring = 0
    alpha = 1.0
    substeps = int(cfg[CFG_SUBSTEPS])
    nhc_on = cfg[CFG_NHC_ON] > 0.0
    out_alpha[0] = alpha
    record_output(t0, X, P, n, out_t, out_x, out_P, counts)
    t_cur = t0
    i = i0
    for k in range(stops.shape[0]):
        stop = stops[k]
        t = stop[ST_T]
        i = propagate_span(
            X, imu_t, imu, i, t_cur, u, t, substeps, cfg[CFG_MAX_STEP], cfg[CFG_GAP_S], u_end,
            work, acc, True,
        )  # fmt: skip
        u[:] = u_end
        t_cur = t
        transition(X, acc, noise, n, Phi, Qd)
        fading = alpha * alpha if stop[ST_FIX] >= 0 else 1.0
        P[:, :] = fading * (Phi @ P @ Phi.T) + Qd
        m, nb_ = epoch_layout(stop, fix, obs, obs_start, nhc_on, rows, blocks)
        if m > 0:
            ma = ekf_prepare(
                t, X, P, n, rows, m, blocks, nb_, fix, obs, u[3:6], lever_b, nhc_sigma, gate,
                cfg, reject_since, z, r, nu, H, S, acc_rows, inn_i, inn_f, ev_i, ev_f, counts,
            )  # fmt: skip
            if ma > 0:
                dx, ok = joseph_update(P, n, H, S, r, nu, acc_rows, ma)
                if ok:
                    inject(X, dx, n)
            if stop[ST_FIX] >= 0:
                n_ring = push_residuals(ring, n_ring, rows, nu, S, m)
                mean_in, cov_in = residual_inputs(ring, n_ring)
                alpha = infer_alpha(mean_in, cov_in, fz, rules)
        ok = keep_pd(P, n, L, t, ev_i, ev_f, counts)
        status = check_state(X, P, n, ones, cfg) if ok else STATUS_INDEFINITE
        if status != STATUS_OK:
            return fail(t, status, ev_i, ev_f, counts)
        if stop[ST_OUT] > 0:
            j = counts[CNT_OUT]
            if j < out_alpha.shape[0]:
                out_alpha[j] = alpha
            record_output(t, X, P, n, out_t, out_x, out_P, counts)
        counts[CNT_STOP] = k + 1
    return STATUS_OK
