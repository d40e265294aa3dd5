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

from navreplay.pipeline._jit import njit
from navreplay.pipeline.estimation.core.gating import (
    STATUS_INDEFINITE,
    STATUS_OK,
    fail,
    gate_blocks,
    gating_cov,
    keep_pd,
    record_output,
)
from navreplay.pipeline.estimation.core.linalg import (
    innovation_cov,
    joseph_update,
    propagate_cov,
)
from navreplay.pipeline.estimation.core.runlog import CNT_OUT, CNT_STOP, GatedBlocks, RunLog
from navreplay.pipeline.estimation.ins.kernels.common import (
    check_state,
    close_gating,
    epoch_buffers,
    fill_still,
    reset_timed_out,
    rest_plausible,
)
from navreplay.pipeline.estimation.ins.kernels.records import (
    Epoch,
    EpochBuffers,
    Schedule,
    Settings,
    SmoothLog,
)
from navreplay.pipeline.estimation.ins.kernels.smoother import (
    SM_PRIOR,
    changed,
    copy_mat,
    copy_vec,
    pool_put,
    record_post,
    record_prior,
    record_start,
    sm_on,
)
from navreplay.pipeline.estimation.ins.models.ins import (
    X_VEL,
    ImuSpan,
    Stepping,
    inject,
    propagate_span,
    span_work,
)
from navreplay.pipeline.estimation.ins.models.ins_errors import second_order_noise, transition
from navreplay.pipeline.estimation.ins.models.measurement import (
    K_PR,
    ST_OUT,
    ST_STILL,
    ST_T,
    STILL_COLS,
    epoch_h,
    epoch_jac,
    epoch_layout,
    epoch_z,
    gate_shift,
    scale_fix_rows,
)
from navreplay.pipeline.nav.earth import F64


@njit(cache=True, error_model="numpy", inline="always")
def ekf_prepare(
    ep: Epoch,
    X: F64,
    P: F64,
    fix: F64 | None,
    obs: F64 | None,
    cfg: Settings,
    buf: EpochBuffers,
    log: RunLog,
) -> int:
    """Measurement front end of one EKF epoch ``ep``: values, Jacobians, gating, timeout
    resets.

    Fills ``z``, ``r`` (variances), ``nu = z - h(X)``, ``H`` (m, n) and the prior innovation
    covariance ``S = H P H^T + R``; gates every block; resets the covariance of a stream
    rejected for longer than the timeout (modifying ``P``) and gates again; records the
    innovations and events; writes the accepted row indices into ``acc_rows``.

    Returns:
        the number of accepted rows.
    """
    t_ns, m, nb_, w_ib_b = ep.t_ns, ep.m, ep.nb, ep.w_ib_b
    n, lever_b, gate = cfg.n, cfg.lever_b, cfg.gate
    rows, blocks, z, r, nu, H, S = buf.rows, buf.blocks, buf.z, buf.r, buf.nu, buf.H, buf.S
    ref = X[:3].copy()
    epoch_z(rows, m, fix, obs, ref, cfg.nhc_sigma, ep.still, z, r)
    scale_fix_rows(rows, m, ep.r_scale, r)
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
        g = GatedBlocks(nu, gating_cov(S, dr, m), blocks, nb_, nis, accepted)
        gate_blocks(nu, g.S, blocks, nb_, gate, nis, accepted, gwork)
        if attempt == 1 or not reset_timed_out(t_ns, P, g, buf, ones, cfg, log):
            break
    return close_gating(t_ns, g, cfg, buf, log)


@njit(cache=True, error_model="numpy")
def run_ekf(
    x0: F64,
    P0: F64,
    sched: Schedule,
    fix: F64 | None,
    obs: F64 | None,
    cfg: Settings,
    log: RunLog,
    sm: SmoothLog,
) -> int:
    """Replay the error-state EKF from ``x0, P0`` at ``sched.t0`` over every stop.

    Args:
        x0: initial full state (18,); P0: initial error covariance (n, n).
        sched: the segment's IMU samples and stops (``records.Schedule``).
        fix, obs: the measurements (``models.measurement``); the one the filter does not read
            is None, and the kernel compiled for it carries no code for it.
        cfg: the settings (``records.Settings``); log: what the run writes (``records.RunLog``).
        sm: what the backward pass needs (``records.SmoothLog``; no rows: not recorded).

    Returns:
        a ``common.STATUS_*`` code (``log.counts[CNT_T_FAIL]`` holds the time of a failure).
    """
    n, m_max = cfg.n, sched.m_max
    X = x0.copy()
    P = P0.copy()
    ones = np.ones(n)
    L = np.empty((n, n))
    Phi = np.empty((n, n))
    Qd = np.empty((n, n))
    tmp = np.empty((n, n))
    step = Stepping(cfg.substeps, cfg.max_step_s, cfg.gap_s)
    sw = span_work()
    u = sched.u0.copy()
    buf = epoch_buffers(m_max, n, sched.t0)
    still = np.zeros(STILL_COLS)
    unit = np.ones(K_PR)
    smoothing = sm_on(sm)
    P_prop = np.empty((n, n)) if smoothing else np.empty((0, 0))
    if smoothing:
        record_start(sm, X, sw.acc, P, ones, log.counts[CNT_OUT])
    record_output(sched.t0, X, P, log)
    t_cur = sched.t0
    i = sched.i0
    stops = sched.stops
    for k in range(stops.shape[0]):
        stop = stops[k]
        t = stop[ST_T]
        i_prev = i
        i = propagate_span(X, ImuSpan(sched.imu_t, sched.imu, i, t_cur, u, t), step, sw, True)
        for j in range(6):
            u[j] = sw.u_end[j]
        if stop[ST_STILL] > 0:
            fill_still(still, sched.imu, i_prev, i, u[3:6], (t - t_cur) * 1e-9, cfg)
        t_cur = t
        second_order_noise(P, sw.acc, cfg.noise)
        if smoothing:
            record_prior(sm, k + 1, X, sw.acc)
        transition(X, sw.acc, cfg.noise, n, Phi, Qd)
        propagate_cov(P, Phi, Qd, n, tmp)
        if smoothing:
            copy_mat(P_prop, P)
        at_rest = rest_plausible(stop, X[X_VEL : X_VEL + 3], P, cfg)
        m, nb_ = epoch_layout(
            stop, fix, obs, sched.obs_start, cfg.nhc_on, at_rest, buf.rows, buf.blocks
        )
        if m > 0:
            ep = Epoch(t, m, nb_, u[3:6], still, unit)
            ma = ekf_prepare(ep, X, P, fix, obs, cfg, buf, log)
            if smoothing and changed(P, P_prop, n):  # a stream reset: not the transition's
                sm.rows[k + 1, SM_PRIOR] = pool_put(sm, P, ones)
            if ma > 0:
                dx, ok = joseph_update(P, n, buf.H, buf.S, buf.r, buf.nu, buf.acc_rows, ma)
                if ok:
                    inject(X, dx, n)
                    if smoothing:
                        copy_vec(sm.dx[k + 1], dx, n)
        ok = keep_pd(P, n, L, t, log.ev_i, log.ev_f, log.counts)
        status = check_state(X, P, ones, cfg) if ok else STATUS_INDEFINITE
        if status != STATUS_OK:
            return fail(t, status, log.ev_i, log.ev_f, log.counts)
        if smoothing:
            record_post(sm, k + 1, P, ones, log.counts[CNT_OUT] if stop[ST_OUT] > 0 else -1)
        if stop[ST_OUT] > 0:
            record_output(t, X, P, log)
        log.counts[CNT_STOP] = k + 1
    return STATUS_OK
