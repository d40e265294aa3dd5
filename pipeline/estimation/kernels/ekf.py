"""The error-state EKF replay loop, compiled whole with numba (``cache=True``).

Per stop of the schedule (``models.measurement`` layout): propagate the full nominal state
through the IMU samples (``ins.propagate_span``, RK4), propagate the error covariance with the
span's transition ``P <- Phi P Phi^T + Qd`` (``ins.transition``), then, if the stop carries
measurements, one joint update of every accepted block: chi-square gating per block, timeout
resets, Joseph-form covariance update, injection of the error estimate into the nominal state
(error reset). The covariance is symmetrized and checked positive definite at every stop and
the NaN barrier (``common.check_state``) ends the run on divergence.

``ekf_prepare`` is also the filterpy backend's update front end (same gating, same resets);
only the Joseph update itself is done by filterpy there. ``ekf_prepare`` and
``joseph_update`` are inlined into the loop at compile time (see "Compile time" in
``kernels.ukf``).
"""

from __future__ import annotations

import numpy as np

from pipeline._jit import njit
from pipeline.estimation.kernels.common import (
    CFG_GAP_S,
    CFG_MAX_STEP,
    CFG_NHC_ON,
    CFG_SUBSTEPS,
    CFG_TIMEOUT_S,
    CNT_STOP,
    EV_RESET,
    N_STREAMS,
    STATUS_INDEFINITE,
    STATUS_OK,
    accepted_rows,
    check_state,
    cho_solve,
    cholesky,
    fail,
    gate_blocks,
    gating_cov,
    inflate_for_stream,
    innovation_cov,
    keep_pd,
    propagate_cov,
    record_event,
    record_innovations,
    record_output,
    streams_to_reset,
    update_reject_since,
)
from pipeline.estimation.models.ins import ACC_DIM, inject, propagate_span
from pipeline.estimation.models.ins_errors import transition
from pipeline.estimation.models.measurement import (
    ST_OUT,
    ST_T,
    epoch_h,
    epoch_jac,
    epoch_layout,
    epoch_z,
    gate_shift,
)
from pipeline.nav.earth import F64, I64


@njit(cache=True, error_model="numpy", inline="always")
def ekf_prepare(
    t_ns: int,
    X: F64,
    P: F64,
    n: int,
    rows: I64,
    m: int,
    blocks: I64,
    nb_: int,
    fix: F64 | None,
    obs: F64 | None,
    w_ib_b: F64,
    lever_b: F64,
    nhc_sigma: F64,
    gate: F64,
    cfg: F64,
    reject_since: I64,
    z: F64,
    r: F64,
    nu: F64,
    H: F64,
    S: F64,
    acc_rows: I64,
    inn_i: I64,
    inn_f: F64,
    ev_i: I64,
    ev_f: F64,
    counts: I64,
) -> int:
    """Measurement front end of one EKF epoch: values, Jacobians, gating, timeout resets.

    Fills ``z``, ``r`` (variances), ``nu = z - h(X)``, ``H`` (m, n) and the prior innovation
    covariance ``S = H P H^T + R``; gates every block; resets the covariance of a stream
    rejected for longer than the timeout (modifying ``P``) and gates again; records the
    innovations and events; writes the accepted row indices into ``acc_rows``.

    Returns:
        the number of accepted rows.
    """
    ref = X[:3].copy()
    epoch_z(rows, m, fix, obs, ref, nhc_sigma, z, r)
    dr = np.empty(m)
    gate_shift(rows, m, fix, r, dr)
    hx = np.empty(m)
    epoch_h(X, rows, m, obs, ref, w_ib_b, lever_b, hx)
    epoch_jac(X, rows, m, obs, w_ib_b, lever_b, n, H)
    for k in range(m):
        nu[k] = z[k] - hx[k]
    nis = np.empty(nb_)
    accepted = np.empty(nb_, np.int64)
    gwork = np.empty((3, 6))
    ones = np.ones(n)
    PHt = np.empty((n, m))
    for attempt in range(2):
        innovation_cov(H, P, r, m, n, PHt, S)
        Sg = gating_cov(S, dr, m)
        gate_blocks(nu, Sg, blocks, nb_, gate, nis, accepted, gwork)
        if attempt == 1:
            break
        reset = streams_to_reset(t_ns, blocks, nb_, accepted, reject_since, cfg[CFG_TIMEOUT_S])
        if reset.sum() == 0:
            break
        for s in range(N_STREAMS):
            if reset[s]:
                big = inflate_for_stream(P, n, s, nu, blocks, nb_, ones, cfg)
                record_event(ev_i, ev_f, counts, t_ns, EV_RESET, s, -1, big)
    record_innovations(
        t_ns, nu, Sg, blocks, nb_, nis, accepted, gate, inn_i, inn_f, counts, ev_i, ev_f
    )
    update_reject_since(t_ns, blocks, nb_, accepted, reject_since)
    return accepted_rows(blocks, nb_, accepted, acc_rows)


@njit(cache=True, error_model="numpy", inline="always")
def joseph_update(
    P: F64, n: int, H: F64, S: F64, r: F64, nu: F64, acc_rows: I64, ma: int
) -> tuple[F64, bool]:
    """Kalman update of the accepted rows in Joseph form; returns (dx, ok).

    ``K = P H^T S^-1`` (by Cholesky), ``P <- (I - K H) P (I - K H)^T + K R K^T``, symmetrized.
    ``ok`` is False (and nothing changes) if the accepted ``S`` is not positive definite.
    """
    Ha = np.empty((ma, n))
    Sa = np.empty((ma, ma))
    for i in range(ma):
        for j in range(n):
            Ha[i, j] = H[acc_rows[i], j]
        for j in range(ma):
            Sa[i, j] = S[acc_rows[i], acc_rows[j]]
    L = np.empty((ma, ma))
    dx = np.zeros(n)
    if not cholesky(Sa, ma, L):
        return dx, False
    Kt = np.empty((ma, n))  # (P H^T)^T, then S^-1 (P H^T)^T = K^T
    for i in range(ma):
        for j in range(n):
            a = 0.0
            for k in range(n):
                a += Ha[i, k] * P[k, j]
            Kt[i, j] = a
    cho_solve(L, ma, Kt, n)
    for j in range(n):
        a = 0.0
        for i in range(ma):
            a += Kt[i, j] * nu[acc_rows[i]]
        dx[j] = a
    A = np.empty((n, n))  # I - K H
    for i in range(n):
        for j in range(n):
            a = 1.0 if i == j else 0.0
            for k in range(ma):
                a -= Kt[k, i] * Ha[k, j]
            A[i, j] = a
    AP = np.empty((n, n))
    for i in range(n):
        for j in range(n):
            a = 0.0
            for k in range(n):
                a += A[i, k] * P[k, j]
            AP[i, j] = a
    for i in range(n):
        for j in range(i, n):
            a = 0.0
            for k in range(n):
                a += AP[i, k] * A[j, k]
            for k in range(ma):
                a += Kt[k, i] * r[acc_rows[k]] * Kt[k, j]
            P[i, j] = a
            P[j, i] = a
    return dx, True


@njit(cache=True, error_model="numpy")
def run_ekf(
    x0: F64,
    P0: F64,
    n: int,
    t0: int,
    i0: int,
    u0: F64,
    imu_t: I64,
    imu: F64,
    stops: I64,
    fix: F64 | None,
    obs: F64 | None,
    obs_start: I64,
    cfg: F64,
    noise: F64,
    lever_b: F64,
    nhc_sigma: F64,
    gate: F64,
    m_max: int,
    out_t: I64,
    out_x: F64,
    out_P: F64,
    inn_i: I64,
    inn_f: F64,
    ev_i: I64,
    ev_f: F64,
    counts: I64,
) -> int:
    """Replay the error-state EKF from ``x0, P0`` at ``t0`` over every stop.

    Args:
        x0: initial full state (18,); P0: initial error covariance (n, n).
        n: error-state dimension (15 loose, 17 tight).
        t0: start time, ns; i0: first IMU sample after t0; u0: IMU input at t0 (6,).
        imu_t, imu: the IMU samples (see ``ins.propagate_span``).
        stops, fix, obs, obs_start: schedule and measurements (``models.measurement``).
        cfg: settings (``common.CFG_*``); noise: ``ins.noise_vector``; lever_b: antenna lever
            arm (3,); nhc_sigma: NHC 1-sigma (2,); gate: chi-square threshold by dimension.
        m_max: most rows of one epoch.
        out_t, out_x, out_P: outputs at the stops flagged for output (and at t0).
        inn_i, inn_f, ev_i, ev_f: innovation and event logs; counts: ``common.CNT_*``.

    Returns:
        a ``common.STATUS_*`` code (``counts[CNT_T_FAIL]`` holds the time of a failure).
    """
    X = x0.copy()
    P = P0.copy()
    ones = np.ones(n)
    L = np.empty((n, n))
    Phi = np.empty((n, n))
    Qd = np.empty((n, n))
    tmp = np.empty((n, n))
    work = np.zeros((9, 10))
    acc = np.zeros(ACC_DIM)
    u = u0.copy()
    u_end = np.empty(6)
    rows = np.empty((m_max, 2), np.int64)
    blocks = np.empty((m_max, 4), np.int64)
    z = np.empty(m_max)
    r = np.empty(m_max)
    nu = np.empty(m_max)
    H = np.empty((m_max, n))
    S = np.empty((m_max, m_max))
    acc_rows = np.empty(m_max, np.int64)
    reject_since = -np.ones(N_STREAMS, np.int64)
    substeps = int(cfg[CFG_SUBSTEPS])
    nhc_on = cfg[CFG_NHC_ON] > 0.0
    record_output(t0, X, P, n, out_t, out_x, out_P, counts)
    t_cur = t0
    i = i0
    for k in range(stops.shape[0]):
        stop = stops[k]
        t = stop[ST_T]
        i = propagate_span(
            X,
            imu_t,
            imu,
            i,
            t_cur,
            u,
            t,
            substeps,
            cfg[CFG_MAX_STEP],
            cfg[CFG_GAP_S],
            u_end,
            work,
            acc,
            True,
        )
        for j in range(6):
            u[j] = u_end[j]
        t_cur = t
        transition(X, acc, noise, n, Phi, Qd)
        propagate_cov(P, Phi, Qd, n, tmp)
        m, nb_ = epoch_layout(stop, fix, obs, obs_start, nhc_on, rows, blocks)
        if m > 0:
            ma = ekf_prepare(
                t,
                X,
                P,
                n,
                rows,
                m,
                blocks,
                nb_,
                fix,
                obs,
                u[3:6],
                lever_b,
                nhc_sigma,
                gate,
                cfg,
                reject_since,
                z,
                r,
                nu,
                H,
                S,
                acc_rows,
                inn_i,
                inn_f,
                ev_i,
                ev_f,
                counts,
            )
            if ma > 0:
                dx, ok = joseph_update(P, n, H, S, r, nu, acc_rows, ma)
                if ok:
                    inject(X, dx, n)
        ok = keep_pd(P, n, L, t, ev_i, ev_f, counts)
        status = check_state(X, P, n, ones, cfg) if ok else STATUS_INDEFINITE
        if status != STATUS_OK:
            return fail(t, status, ev_i, ev_f, counts)
        if stop[ST_OUT] > 0:
            record_output(t, X, P, n, out_t, out_x, out_P, counts)
        counts[CNT_STOP] = k + 1
    return STATUS_OK
